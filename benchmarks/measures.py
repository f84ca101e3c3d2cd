"""Error measures shared by the benchmarks: trajectory and gradient errors."""

from __future__ import annotations

import numpy as np


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
