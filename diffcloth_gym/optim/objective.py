"""``objective(theta) -> (loss, grad)``: one recorded rollout and one backward on one reused
simulator, with a step counter and an evaluation history.

How steps are counted (the paper's rule, Sec. 6 and Table 3: "the time steps shown for
L-BFGS-B include both forward simulation and backward propagation"; its Hat 11,200 = 2 x
5,600): every simulated step counts one, and every recorded step the adjoint passes back
through counts one. An evaluation with a gradient over an N-step rollout costs 2N steps, one
without a gradient (what the evolution strategies use) N. The counters count what ran: a
rollout stopped by an error counts the steps it completed.

Accuracy: the simulator runs at the ``gradient`` solver preset by default (tolerance 1e-11),
for evaluations with and without a gradient alike, so every method optimizes the same
function, the one whose gradient backward computes.
"""

from __future__ import annotations

import time
import warnings
from typing import Callable

import numpy as np

from diffcloth_gym.errors import ConvergenceWarning, InputError
from diffcloth_gym.optim.losses import Loss
from diffcloth_gym.optim.parameterization import Parameterization, check_theta, from_unit, to_unit


class BudgetExhausted(Exception):
    """Raised instead of running an evaluation that would take the step count past the budget."""


class Objective:
    """The loss of an N-step rollout as a function of a parameterization's ``theta``.

    ``obj(theta)`` returns ``(loss, dL/dtheta)`` (recorded rollout + one backward, 2N steps);
    ``obj.loss(theta)`` the loss alone (N steps). ``x0``/``v0`` are the rollout's start (default:
    the rest shape, at rest). ``preset`` is applied with ``sim.set_solver`` (None: keep the
    simulator's settings); ``backward`` holds keyword arguments of ``Simulator.backward``.
    ``budget`` (steps, None: unlimited) makes an evaluation that would exceed it raise
    :class:`BudgetExhausted` without running.
    """

    def __init__(self, sim, parameterization: Parameterization, loss: Loss, steps: int, x0=None, v0=None,
                 preset: str | None = "gradient", backward: dict | None = None, budget: int | None = None):
        if not isinstance(steps, (int, np.integer)) or steps < 1:
            raise InputError(f"steps must be a positive integer, got {steps!r}")
        self.sim, self.param, self.loss_fn, self.steps = sim, parameterization, loss, int(steps)
        self.x0, self.v0 = x0, v0
        self.backward_options = dict(backward or {})
        if preset is not None:
            sim.set_solver(preset=preset)
        self.budget = budget
        self.callbacks: list[Callable[[dict], None]] = []
        self.reset_counters()

    # -- counters ------------------------------------------------------------------------
    def reset_counters(self) -> None:
        """Zeroes the step counters and the history (a driver calls it when a run starts)."""
        self.forward_steps = 0
        self.backward_steps = 0
        self.history: list[dict] = []
        self.best_loss = np.inf
        self.best_theta: np.ndarray | None = None
        self.unconverged_steps = 0
        self.gradient_warnings: list[str] = []
        self._t0 = time.perf_counter()

    @property
    def steps_used(self) -> int:
        """Simulated steps so far, forward plus backward (see the module docstring)."""
        return self.forward_steps + self.backward_steps

    def _charge(self, cost: int) -> None:
        if self.budget is not None and self.steps_used + cost > self.budget:
            raise BudgetExhausted(f"{self.steps_used} + {cost} steps would exceed the budget of {self.budget}")

    def _log(self, theta: np.ndarray, loss: float, grad_norm: float | None) -> None:
        if loss < self.best_loss:
            self.best_loss, self.best_theta = loss, theta.copy()
        entry = {"evaluation": len(self.history), "steps": self.steps_used, "loss": loss, "best": self.best_loss,
                 "gradient": grad_norm is not None, "grad_norm": grad_norm,
                 "seconds": time.perf_counter() - self._t0}
        self.history.append(entry)
        for cb in self.callbacks:
            cb(entry)

    # -- rollouts ------------------------------------------------------------------------
    def rollout(self, theta, record: bool = False, contacts: bool = False):
        """Simulates the rollout for ``theta``; returns positions (N, n, 3) and, with
        ``contacts``, each step's contacts as ``{(node_a, node_b, obstacle): branch}``.
        Counts its steps (not logged as an evaluation)."""
        theta = check_theta(self.param, theta)
        inp = self.param.inputs(theta, self.steps)
        sim = self.sim
        sim.set_recording(False)
        if inp.params:
            sim.set_params(**inp.params)
        sim.set_recording(record)
        sim.reset(self.x0, self.v0)
        xs = np.empty((self.steps, sim.num_nodes, 3))
        branches = []
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", ConvergenceWarning)
            for k in range(self.steps):
                sim.step(attachment_targets=None if inp.targets is None else inp.targets[k],
                         external_forces=None if inp.forces is None else inp.forces[k])
                self.forward_steps += 1
                xs[k] = sim.positions
                if contacts:
                    c = sim.contacts()
                    branches.append({(int(a), int(b), int(o)): int(br) for a, b, o, br in
                                     zip(c["node_a"], c["node_b"], c["obstacle"], c["branch"])})
        # Steps at the iteration cap are counted, not hidden (see unconverged_steps).
        self.unconverged_steps += sum(issubclass(w.category, ConvergenceWarning) for w in caught)
        for w in caught:
            if not issubclass(w.category, ConvergenceWarning):
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        return (xs, branches) if contacts else xs

    def loss(self, theta) -> float:
        """The loss alone (N steps)."""
        self._charge(self.steps)
        theta = check_theta(self.param, theta)
        value, _ = self.loss_fn(self.rollout(theta))
        self._log(theta, float(value), None)
        return float(value)

    def __call__(self, theta) -> tuple[float, np.ndarray]:
        """``(loss, dL/dtheta)``: a recorded rollout and one backward (2N steps)."""
        self._charge(2 * self.steps)
        theta = check_theta(self.param, theta)
        xs = self.rollout(theta, record=True)
        value, dl_dx = self.loss_fn(xs)
        g = self.sim.backward(dl_dx=dl_dx, **self.backward_options)
        self.backward_steps += self.steps
        for w in g["warnings"]:
            if w not in self.gradient_warnings:
                self.gradient_warnings.append(w)
                warnings.warn(f"diffcloth gradient: {w}", stacklevel=2)
        grad = self.param.chain(theta, g, self.steps)
        self._log(theta, float(value), float(np.linalg.norm(grad)))
        return float(value), grad

    # -- the unit box the drivers work in -----------------------------------------------
    def unit_loss(self, u) -> float:
        return self.loss(from_unit(self.param, u))

    def unit_value_and_grad(self, u) -> tuple[float, np.ndarray]:
        lo, hi = self.param.bounds
        value, grad = self(from_unit(self.param, u))
        return value, grad * (hi - lo)

    def to_unit(self, theta) -> np.ndarray:
        return to_unit(self.param, theta)

    def from_unit(self, u) -> np.ndarray:
        return from_unit(self.param, u)
