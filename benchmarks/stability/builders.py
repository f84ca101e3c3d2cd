"""Scene builders of the stability suite: dict configs after the shipped scenes
(``diffcloth_gym/configs/*.toml``), with the knobs the hard cases turn, plus closed forms of the
slope they are checked against and helpers for OBJ meshes and random end-effector paths."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Callable

import numpy as np

GRAVITY = 9.8
SLOPE_DEG = 42.0


def napkin(rows: int, width: float = 1.0, plane: str = "xz", h: float = 0.01, k_stretch: float = 200.0,
           k_bend: float = 0.01, strain_limits: tuple[float, float] | None = None,
           effects: tuple[str, ...] = (), **more: Any) -> dict:
    """A square ``rows x rows`` grid napkin of side ``width`` (density 0.2) with gravity, stretch
    and bend, plus ``effects``; ``more`` adds top-level config tables."""
    material: dict = {"density": 0.2, "k_stretch": k_stretch, "k_bend": k_bend}
    if strain_limits is not None:
        material["strain_limits"] = list(strain_limits)
    cfg = {"h": h, "effects": ["gravity", "stretch", "bend", *effects],
           "mesh": {"kind": "grid", "rows": rows, "cols": rows, "width": width, "height": width, "plane": plane},
           "material": material}
    cfg.update(more)
    return cfg


def corners(rows: int) -> list[int]:
    """Corner node indices of a square grid (node (r, c) is ``r * rows + c``)."""
    return [0, rows - 1, (rows - 1) * rows, rows * rows - 1]


def slope_config(mu: float, rows: int, h: float = 0.01, k_stretch: float = 50.0) -> dict:
    """``configs/slope.toml``: a 2 m x 6 m ribbon lying on a plane inclined at 42 degrees, one
    contact thickness above it, every node in contact."""
    a = math.radians(SLOPE_DEG)
    thickness = 0.01
    normal = [0.0, math.cos(a), math.sin(a)]
    return {
        "h": h, "effects": ["gravity", "stretch", "obstacle_contact", "friction"],
        "mesh": {"kind": "grid", "rows": rows, "cols": rows, "width": 2.0, "height": 6.0, "plane": "xz"},
        "placement": {"rotate_deg": [SLOPE_DEG, 0.0, 0.0], "translate": [thickness * c for c in normal]},
        "material": {"density": 0.2, "k_stretch": k_stretch},
        "contact": {"thickness": thickness},
        "obstacles": [{"mu": mu, "shape": {"kind": "plane", "point": [0.0, 0.0, 0.0], "normal": normal}}],
    }


def downhill() -> np.ndarray:
    """Unit vector down the slope of :func:`slope_config`."""
    a = math.radians(SLOPE_DEG)
    return np.array([0.0, -math.sin(a), math.cos(a)])


def sliding_distance(mu: float, h: float, steps: int) -> float:
    """Downhill travel of a rigid body released on the 42-degree slope after ``steps`` implicit
    Euler steps: ``a h^2 N (N + 1) / 2`` with ``a = g (sin - mu cos)``, or 0 if it sticks."""
    a = math.radians(SLOPE_DEG)
    acc = GRAVITY * (math.sin(a) - mu * math.cos(a))
    return max(acc, 0.0) * h * h * steps * (steps + 1) / 2


def sphere_config(mu: float, rows: int, h: float = 1 / 180, k_stretch: float = 150.0) -> dict:
    """``configs/sphere.toml``: a 6 m cloth dropped from 0.6 m above a sphere of radius 2, with
    self-collision (radius 0.1)."""
    return {
        "h": h, "effects": ["gravity", "stretch", "bend", "obstacle_contact", "friction", "self_collision"],
        "mesh": {"kind": "grid", "rows": rows, "cols": rows, "width": 6.0, "height": 6.0, "plane": "xz"},
        "placement": {"translate": [0.0, 2.6, 0.0]},
        "material": {"density": 0.3, "k_stretch": k_stretch, "k_bend": 1e-5},
        "contact": {"thickness": 0.02},
        "obstacles": [{"mu": mu, "shape": {"kind": "sphere", "center": [0.0, 0.0, 0.0], "radius": 2.0}}],
        "self_collision": {"radius": 0.1, "mu": 0.1},
    }


def crumple_config(shape: str, rows: int, width: float, radius: float, drop: float, turn_deg: float) -> dict:
    """A napkin dropped into the bowl of ``configs/bowl.toml`` or the pit of
    ``configs/pyramid.toml`` (same material, thickness 5 mm, obstacle mu 0.3), with
    self-collision of ``radius`` (mu 0.2), released ``drop`` m high and turned ``turn_deg``
    about the vertical so that its corners fold against the walls."""
    obstacle = {
        "bowl": {"kind": "bowl", "center": [0.0, 1.0, 0.0], "radius": 1.0, "rim_height": 0.7},
        "pyramid": {"kind": "pyramid_pit", "apex": [0.0, 0.0, 0.0], "half_width": 0.5, "height": 0.6},
    }[shape]
    return {
        "h": 0.005,
        "effects": ["gravity", "stretch", "bend", "obstacle_contact", "friction", "self_collision"],
        "mesh": {"kind": "grid", "rows": rows, "cols": rows, "width": width, "height": width, "plane": "xz"},
        "placement": {"translate": [0.0, drop, 0.0], "rotate_deg": [0.0, turn_deg, 0.0]},
        "material": {"density": 0.2, "k_stretch": 400.0, "k_bend": 0.001, "strain_limits": [0.95, 1.05]},
        "contact": {"thickness": 0.005},
        "obstacles": [{"mu": 0.3, "shape": obstacle}],
        "self_collision": {"radius": radius, "mu": 0.2},
    }


def write_grid_obj(path: Path, n: int, width: float, sliver: float | None = None) -> Path:
    """Writes an ``n x n`` grid of side ``width`` in the xz plane as OBJ. With ``sliver``, an
    extra node column is inserted ``sliver * spacing`` to the right of the middle column, making
    a strip of ``2 (n - 1)`` slivers of aspect ratio ``sliver`` (width over height)."""
    xs = list(np.linspace(-width / 2, width / 2, n))
    if sliver is not None:
        c = n // 2
        xs.insert(c + 1, xs[c] + sliver * (xs[1] - xs[0]))
    zs = np.linspace(-width / 2, width / 2, n)
    cols = len(xs)
    lines = [f"v {float(x)!r} 0.0 {float(z)!r}" for z in zs for x in xs]
    for r in range(n - 1):
        for c in range(cols - 1):
            a, b = r * cols + c + 1, r * cols + c + 2  # OBJ indices are 1-based
            lines += [f"f {a} {b} {b + cols}", f"f {a} {b + cols} {a + cols}"]
    path.write_text("\n".join(lines) + "\n")
    return path


def smooth_walk(rng: np.random.Generator, max_speed: float, waves: int = 3) -> Callable[[float], np.ndarray]:
    """A smooth random 3D path ``p(t)`` with ``p(0) = 0``: per axis a sum of ``waves`` sinusoids
    (1-4 rad/s) whose amplitudes are scaled so that each axis' speed is at most ``max_speed``."""
    omega = rng.uniform(1.0, 4.0, (waves, 3))
    phase = rng.uniform(0.0, 2 * np.pi, (waves, 3))
    amp = rng.uniform(0.5, 1.0, (waves, 3))
    amp *= max_speed / (amp * omega).sum(axis=0)  # |p_i'(t)| <= sum_k a_k w_k = max_speed
    return lambda t: (amp * (np.sin(omega * t + phase) - np.sin(phase))).sum(axis=0)
