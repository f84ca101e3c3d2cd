"""Losses on a rollout's positions, each with its gradient, composable with ``+`` and ``*``.

A loss is called with the positions after every step, ``xs`` (N, n, 3), and returns ``(value,
dl_dx)`` where ``dl_dx`` is a dict ``{step: (n, 3) array}`` holding only the steps the loss
depends on (``Simulator.backward`` accepts it as is: a terminal loss needs no padding).
``step`` arguments count like Python indices (``-1``: the final step).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from diffcloth_gym.errors import InputError


class Loss:
    """Base class: subclasses implement ``__call__(xs) -> (value, {step: dl_dx})``."""

    def __call__(self, xs: np.ndarray) -> tuple[float, dict]:
        raise NotImplementedError

    def __add__(self, other: "Loss") -> "Loss":
        return Sum([self, other])

    def __mul__(self, w: float) -> "Loss":
        return Sum([self], [float(w)])

    __rmul__ = __mul__


class Sum(Loss):
    """``sum_i w_i L_i``; the gradients of terms on the same step add up."""

    def __init__(self, terms: Sequence[Loss], weights: Sequence[float] | None = None):
        self.terms = list(terms)
        self.weights = [1.0] * len(self.terms) if weights is None else list(weights)

    def __call__(self, xs):
        total, grads = 0.0, {}
        n = len(xs)
        for w, term in zip(self.weights, self.terms):
            v, g = term(xs)
            total += w * v
            for k, a in g.items():
                k = k % n
                grads[k] = grads.get(k, 0.0) + w * a
        return total, grads


def _target(name: str, target, shape) -> np.ndarray:
    t = np.asarray(target, dtype=np.float64)
    if t.shape != tuple(shape) or not np.all(np.isfinite(t)):
        raise InputError(f"{name} must be a finite array of shape {tuple(shape)}, got {t.shape}")
    return t


def _norm_and_grad(d: np.ndarray, squared: bool) -> tuple[float, np.ndarray]:
    """``|d|^2`` and ``2 d``, or ``|d|`` and ``d / |d|`` (0 at d = 0: a subgradient)."""
    if squared:
        return float(np.sum(d * d)), 2.0 * d
    r = float(np.sqrt(np.sum(d * d)))
    return r, (d / r if r > 0 else np.zeros_like(d))


class ShapeMatch(Loss):
    """Distance of step ``step``'s shape to ``target`` (n, 3): ``|x - target|`` (the paper's
    Hat loss, Eqn. 32), squared with ``squared=True``; ``translation=False`` compares shapes
    with both centroids removed (matching the shape wherever it is); ``mean=True`` divides by
    the node count (``squared=True, mean=True`` is the mean squared node distance)."""

    def __init__(self, target, step: int = -1, squared: bool = False, translation: bool = True,
                 mean: bool = False, nodes=None):
        self.target = np.asarray(target, dtype=np.float64)
        self.step, self.squared, self.translation = step, squared, translation
        self.nodes = None if nodes is None else np.asarray(nodes, dtype=np.int64)
        self.mean = mean

    def __call__(self, xs):
        x = xs[self.step]
        sel = slice(None) if self.nodes is None else self.nodes
        t = _target("target", self.target, x[sel].shape)
        d = x[sel] - t
        if not self.translation:
            d = d - d.mean(axis=0)  # the gradient of the centred residual is itself centred
        v, g = _norm_and_grad(d, self.squared)
        scale = 1.0 / len(d) if self.mean else 1.0
        full = np.zeros_like(x)
        full[sel] = scale * g
        return scale * v, {self.step: full}


class KeypointDistance(Loss):
    """``sum_j |x_step[node_j] - point_j|`` (the paper's Sock loss, Eqn. 33, one step)."""

    def __init__(self, nodes, points, step: int = -1):
        self.nodes = np.asarray(nodes, dtype=np.int64)
        self.points = _target("points", points, (len(self.nodes), 3))
        self.step = step

    def __call__(self, xs):
        d = xs[self.step][self.nodes] - self.points
        r = np.linalg.norm(d, axis=1)
        full = np.zeros_like(xs[self.step])
        np.add.at(full, self.nodes, np.where(r[:, None] > 0, d / np.maximum(r, 1e-300)[:, None], 0.0))
        return float(r.sum()), {self.step: full}


class TrajectoryMatch(Loss):
    """Distance to a reference motion ``targets`` (N, n, 3) over every step: ``sum_n |x_n -
    target_n|`` (the paper's T-shirt and Sphere losses), or with ``squared=True`` and
    ``mean=True`` the mean squared node distance over steps and nodes (the reference code's
    ``MATCH_TRAJECTORY``)."""

    def __init__(self, targets, squared: bool = False, mean: bool = False):
        self.targets = np.asarray(targets, dtype=np.float64)
        self.squared, self.mean = squared, mean

    def __call__(self, xs):
        t = _target("targets", self.targets, xs.shape)
        scale = 1.0 / (xs.shape[0] * xs.shape[1]) if self.mean else 1.0
        total, grads = 0.0, {}
        for k in range(len(xs)):
            v, g = _norm_and_grad(xs[k] - t[k], self.squared)
            total += scale * v
            grads[k] = scale * g
        return total, grads


class SmoothL1(Loss):
    """Smooth L1 (Huber with threshold ``beta``) of step ``step``'s positions to ``target``,
    summed over coordinates: ``0.5 d^2 / beta`` below ``beta``, ``|d| - 0.5 beta`` above (the
    reference Hat controller's loss)."""

    def __init__(self, target, step: int = -1, beta: float = 1.0):
        if not beta > 0:
            raise InputError(f"beta must be positive, got {beta}")
        self.target, self.step, self.beta = np.asarray(target, dtype=np.float64), step, float(beta)

    def __call__(self, xs):
        d = xs[self.step] - _target("target", self.target, xs[self.step].shape)
        a = np.abs(d)
        small = a < self.beta
        v = np.where(small, 0.5 * d * d / self.beta, a - 0.5 * self.beta)
        g = np.where(small, d / self.beta, np.sign(d))
        return float(v.sum()), {self.step: g}


class HeightMatch(Loss):
    """``sum_p (x_step[p, axis] - height)^2`` over the nodes ``nodes`` (the paper's Dress loss,
    Eqn. 34: the hemline's heights against the height of the target apex angle; ``axis`` 1 is
    y, up)."""

    def __init__(self, nodes, height: float, step: int = -1, axis: int = 1):
        self.nodes = np.asarray(nodes, dtype=np.int64)
        if self.nodes.ndim != 1 or len(self.nodes) == 0:
            raise InputError("nodes must be a non-empty list of node indices")
        if not np.isfinite(height):
            raise InputError(f"height must be finite, got {height!r}")
        if axis not in (0, 1, 2):
            raise InputError(f"axis must be 0, 1 or 2, got {axis!r}")
        self.height, self.step, self.axis = float(height), step, axis

    def __call__(self, xs):
        d = xs[self.step][self.nodes, self.axis] - self.height
        full = np.zeros_like(xs[self.step])
        np.add.at(full[:, self.axis], self.nodes, 2.0 * d)
        return float(np.sum(d * d)), {self.step: full}


class GroupKeypoints(Loss):
    """``sum_j |mean(x_step[groups_j]) - points_j|``: keypoint distances where each keypoint is
    the centroid of a group of nodes (the Sock's Eqn. 33 as ``Sock-v0`` defines its keypoints);
    ``groups`` (m, k) node indices, ``points`` (m, 3)."""

    def __init__(self, groups, points, step: int = -1):
        self.groups = np.asarray(groups, dtype=np.int64)
        if self.groups.ndim != 2:
            raise InputError(f"groups must be an (m, k) array of node indices, got shape {self.groups.shape}")
        self.points = _target("points", points, (len(self.groups), 3))
        self.step = step

    def __call__(self, xs):
        x = xs[self.step]
        c = x[self.groups].mean(axis=1)
        d = c - self.points
        r = np.linalg.norm(d, axis=1)
        u = np.where(r[:, None] > 0, d / np.maximum(r, 1e-300)[:, None], 0.0) / self.groups.shape[1]
        full = np.zeros_like(x)
        for j in range(len(self.groups)):
            np.add.at(full, self.groups[j], u[j])
        return float(r.sum()), {self.step: full}
