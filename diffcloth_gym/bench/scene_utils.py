"""Helpers shared by the benchmarks: scene configs and error measures."""

from __future__ import annotations

import copy
import tomllib

import numpy as np

from diffcloth_gym.simulator import CONFIG_DIR

#: Effects and config tables that make a scene a contact scene.
CONTACT_EFFECTS = ("obstacle_contact", "friction", "self_collision")
CONTACT_KEYS = ("obstacles", "self_collision", "contact")


def load_scene(name: str, res: int | None = None) -> dict:
    """The shipped config ``configs/<name>.toml`` as a fresh dict; ``res`` sets a grid's
    rows and columns (``res x res`` nodes)."""
    cfg = tomllib.loads((CONFIG_DIR / f"{name}.toml").read_text())
    if res is not None:
        cfg["mesh"].update(rows=res, cols=res)
    return cfg


def contact_free(cfg: dict) -> dict:
    """A copy of ``cfg`` without obstacles, friction and self-collision (the hat hanging from
    its handles, the sock without the leg): isolates the core PD solver and its adjoint."""
    cfg = copy.deepcopy(cfg)
    cfg["effects"] = [e for e in cfg["effects"] if e not in CONTACT_EFFECTS]
    for key in CONTACT_KEYS:
        cfg.pop(key, None)
    return cfg


def trajectory_error(traj: np.ndarray, ref: np.ndarray) -> float:
    """``|X - X_ref| / |X_ref - X_0|`` over a whole rollout (all steps' positions stacked).

    Relative to the reference's displacement, not its positions: the absolute positions are
    dominated by where the scene sits in space, which would make every error look tiny.
    """
    return float(np.linalg.norm(traj - ref) / max(np.linalg.norm(ref - ref[0]), 1e-300))


def compare(got: np.ndarray, ref: np.ndarray) -> tuple[float, float]:
    """``(relative L2 error, cosine similarity)`` of two gradients (flattened). NaN if the
    reference is zero (nothing to compare against)."""
    a, b = np.ravel(got), np.ravel(ref)
    nb, na = float(np.linalg.norm(b)), float(np.linalg.norm(a))
    if nb == 0.0:
        return float("nan"), float("nan")
    rel = float(np.linalg.norm(a - b) / nb)
    cos = float(a @ b / (na * nb)) if na > 0.0 else float("nan")
    return rel, cos
