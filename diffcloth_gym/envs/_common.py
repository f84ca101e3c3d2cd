"""Helpers shared by the task files: argument checking, start sequences, rotations."""

from __future__ import annotations

import math
from numbers import Real
from typing import Any, Mapping

import numpy as np

from ..errors import ConfigError, InputError


def halton(index: int, base: int) -> float:
    """The ``index``-th element (from 1) of the van der Corput sequence in ``base``."""
    f, r = 1.0, 0.0
    while index > 0:
        f /= base
        r += f * (index % base)
        index //= base
    return r


def merge_config(defaults: Mapping[str, Any], config: Mapping[str, Any] | None, env: str) -> dict:
    """``defaults`` updated with ``config``; an unknown key raises ``ConfigError`` naming it."""
    cfg = dict(defaults)
    unknown = sorted(set(config or {}) - set(defaults))
    if unknown:
        raise ConfigError(f"{env}: unknown argument(s) {unknown}; known: {sorted(defaults)}")
    cfg.update(config or {})
    return cfg


def number(cfg: Mapping[str, Any], key: str, lo: float = -math.inf, hi: float = math.inf,
           open_lo: bool = False) -> float:
    """``cfg[key]`` as a float in ``[lo, hi]`` (``(lo, hi]`` with ``open_lo``), else ``ConfigError``."""
    v = cfg[key]
    if isinstance(v, bool) or not isinstance(v, Real) or not math.isfinite(v) or v < lo or v > hi \
            or (open_lo and v == lo):
        raise ConfigError(f"{key} must be a finite number in {'(' if open_lo else '['}{lo}, {hi}], got {v!r}")
    return float(v)


def vector3(cfg: Mapping[str, Any], key: str) -> np.ndarray:
    """``cfg[key]`` as 3 finite floats, else ``ConfigError``."""
    v = cfg[key]
    try:
        a = np.asarray(v, dtype=np.float64)
    except (TypeError, ValueError):
        a = None
    if a is None or a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ConfigError(f"{key} must be 3 finite numbers, got {v!r}")
    return a


def rotation(deg_xyz) -> np.ndarray:
    """``Rz @ Ry @ Rx`` (the scene placement's convention: x, then y, then z)."""
    rx, ry, rz = (math.radians(float(a)) for a in deg_xyz)
    cx, sx, cy, sy, cz, sz = math.cos(rx), math.sin(rx), math.cos(ry), math.sin(ry), math.cos(rz), math.sin(rz)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def start_values(spec: Any, names: tuple[str, ...]) -> list[float]:
    """A start spec as ``len(names)`` finite floats, else ``InputError`` naming ``start``."""
    vals = None
    if not isinstance(spec, (str, bytes, Mapping)):
        try:
            vals = [float(s) for s in spec]
        except (TypeError, ValueError):
            vals = None
    if vals is None or len(vals) != len(names) or not all(math.isfinite(s) for s in vals):
        raise InputError(f"start must be {len(names)} finite numbers ({', '.join(names)}), got {spec!r}")
    return vals
