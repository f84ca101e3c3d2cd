"""What a parameterization is: a flat vector ``theta`` mapped to simulator inputs, with bounds,
and the chain rule back from the backward's gradient dict to ``dL/dtheta``.

Every driver works in the unit box: ``u = (theta - lo) / (hi - lo)`` in ``[0, 1]^d``
(:func:`to_unit`, :func:`from_unit`), so one step size, one CMA-ES sigma and one (1+1)-ES
sigma mean the same fraction of each parameter's range whatever its units.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol, Sequence

import numpy as np

from diffcloth_gym.errors import InputError


@dataclass
class Inputs:
    """What one rollout needs from a parameterization: per-step attachment targets (N, k, 3)
    and external forces (N, n, 3) (None: not driven), and physical parameters by registry name
    (applied with ``Simulator.set_params`` before the rollout)."""

    targets: np.ndarray | None = None
    forces: np.ndarray | None = None
    params: dict = field(default_factory=dict)


class Parameterization(Protocol):
    """A map from ``theta`` (``size`` numbers within ``bounds``) to rollout :class:`Inputs`."""

    size: int
    names: list[str]

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds, each (size,), finite."""

    def inputs(self, theta: np.ndarray, steps: int) -> Inputs:
        """The rollout's inputs for ``theta`` (``steps`` steps)."""

    def chain(self, theta: np.ndarray, grads: dict, steps: int) -> np.ndarray:
        """``dL/dtheta`` (size,) from ``Simulator.backward``'s gradient dict."""


def check_theta(p: Parameterization, theta, name: str = "theta") -> np.ndarray:
    """``theta`` as a float64 vector of the parameterization's size, finite, or InputError."""
    try:
        t = np.asarray(theta, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError) as e:
        raise InputError(f"{name} must be a vector of {p.size} numbers: {e}") from None
    if t.shape != (p.size,):
        raise InputError(f"{name} must have {p.size} entries, got {t.size}")
    if not np.all(np.isfinite(t)):
        raise InputError(f"{name} must be finite")
    return t


def to_unit(p: Parameterization, theta: np.ndarray) -> np.ndarray:
    lo, hi = p.bounds
    return (np.asarray(theta, dtype=np.float64) - lo) / (hi - lo)


def from_unit(p: Parameterization, u: np.ndarray) -> np.ndarray:
    lo, hi = p.bounds
    return lo + np.asarray(u, dtype=np.float64) * (hi - lo)


def check_bounds(name: str, lo, hi, size: int) -> tuple[np.ndarray, np.ndarray]:
    """Broadcasts bounds to (size,), finite with lo < hi, or InputError naming ``name``."""
    lo = np.broadcast_to(np.asarray(lo, dtype=np.float64), (size,)).copy()
    hi = np.broadcast_to(np.asarray(hi, dtype=np.float64), (size,)).copy()
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(lo < hi)):
        raise InputError(f"{name} bounds must be finite with lower < upper")
    return lo, hi


class Fixed:
    """Inputs that are part of a task, not of the optimization (a twirl's attachment targets,
    a fixed force field): no parameters (``size`` 0); stack it beside the parameterization
    being optimized, ``Stack([PhysicalParams(...), Fixed(targets=...)])``. ``targets`` (N, k, 3)
    and ``forces`` (N, n, 3) must cover the rollout's steps."""

    def __init__(self, targets=None, forces=None):
        self.targets = None if targets is None else np.asarray(targets, dtype=np.float64)
        self.forces = None if forces is None else np.asarray(forces, dtype=np.float64)
        for name, a in (("targets", self.targets), ("forces", self.forces)):
            if a is not None and (a.ndim != 3 or a.shape[2] != 3 or not np.all(np.isfinite(a))):
                raise InputError(f"{name} must be a finite (N, k, 3) array, got shape {a.shape}")
        self.size = 0
        self.names: list[str] = []

    @property
    def bounds(self):
        return np.zeros(0), np.zeros(0)

    def inputs(self, theta, steps: int) -> Inputs:
        for name, a in (("targets", self.targets), ("forces", self.forces)):
            if a is not None and len(a) < steps:
                raise InputError(f"Fixed {name} cover {len(a)} steps, the rollout has {steps}")
        return Inputs(targets=None if self.targets is None else self.targets[:steps],
                      forces=None if self.forces is None else self.forces[:steps])

    def chain(self, theta, grads: dict, steps: int) -> np.ndarray:
        return np.zeros(0)


class Stack:
    """Several parameterizations side by side: ``theta`` is their vectors concatenated (e.g. a
    trajectory and a friction coefficient). Inputs are merged; two parts may not drive the same
    input."""

    def __init__(self, parts: Sequence[Parameterization]):
        self.parts = list(parts)
        self.size = sum(p.size for p in self.parts)
        self.names = [n for p in self.parts for n in p.names]
        self._splits = np.cumsum([p.size for p in self.parts])[:-1]

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        b = [p.bounds for p in self.parts]
        return np.concatenate([lo for lo, _ in b]), np.concatenate([hi for _, hi in b])

    def _split(self, theta):
        return np.split(np.asarray(theta, dtype=np.float64), self._splits)

    def inputs(self, theta: np.ndarray, steps: int) -> Inputs:
        out = Inputs()
        for p, t in zip(self.parts, self._split(theta)):
            i = p.inputs(t, steps)
            for name in ("targets", "forces"):
                if getattr(i, name) is not None:
                    if getattr(out, name) is not None:
                        raise InputError(f"two parameterizations drive {name}")
                    setattr(out, name, getattr(i, name))
            clash = set(out.params) & set(i.params)
            if clash:
                raise InputError(f"two parameterizations set {sorted(clash)}")
            out.params.update(i.params)
        return out

    def chain(self, theta: np.ndarray, grads: dict, steps: int) -> np.ndarray:
        return np.concatenate([p.chain(t, grads, steps) for p, t in zip(self.parts, self._split(theta))])
