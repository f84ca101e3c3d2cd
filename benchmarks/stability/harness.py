"""Running a case: step a simulator under a :class:`~benchmarks.stability.metrics.Monitor`,
take its backward, and pack the metrics, bounds and checks into the case's result dict."""

from __future__ import annotations

import warnings
from typing import Any, Callable

import numpy as np

from benchmarks.stability.metrics import BlowUp, Monitor
from diffcloth_gym import ConvergenceWarning, DivergedError, Simulator, SolverError

SIZES = ("ci", "full")


def pick(size: str, ci: Any, full: Any) -> Any:
    """The CI or the full value of a size-dependent setting."""
    if size not in SIZES:
        raise ValueError(f"size must be one of {SIZES}, got {size!r}")
    return ci if size == "ci" else full


def run(sim: Simulator, monitor: Monitor, steps: int,
        targets: Callable[[int], np.ndarray] | None = None,
        loss_grad: Callable[[Simulator], np.ndarray] | None = None,
        after_step: Callable[[int], None] | None = None) -> np.ndarray | None:
    """Steps ``sim`` ``steps`` times under ``monitor``; ``targets(k)`` gives step k's attachment
    targets, ``after_step(k)`` runs after each observed step. Returns the per-step loss
    gradients ``loss_grad(sim)`` stacked (N, n, 3), or None without ``loss_grad`` or when the
    rollout diverged or blew up (recorded in the monitor; such a rollout has no backward)."""
    monitor.start(sim)
    grads = []
    for k in range(steps):
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                sim.step(attachment_targets=None if targets is None else targets(k))
        except DivergedError as e:
            monitor.diverged = f"step {k}: {e}"
            return None
        for w in caught:
            # Steps stopped at the iteration cap are expected in these hard cases: counted in
            # `convergence_warnings` (and `unconverged_steps`) instead of flooding the log.
            if issubclass(w.category, ConvergenceWarning):
                monitor.convergence_warnings += 1
            else:
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        try:
            monitor.observe()
        except BlowUp as e:
            monitor.blew_up = str(e)
            return None
        if after_step is not None:
            after_step(k)
        if loss_grad is not None:
            grads.append(loss_grad(sim))
    return np.asarray(grads) if loss_grad is not None else None


def backward(sim: Simulator, monitor: Monitor, dl_dx: np.ndarray | None) -> dict | None:
    """Krylov backward through the recorded rollout (skipped if it diverged). A
    :class:`~diffcloth_gym.errors.SolverError` is recorded in the monitor (``backward_error``,
    a failed check) and gives None; anything else (a panic: ``InternalError``) propagates."""
    if dl_dx is None:
        return None
    try:
        g = sim.backward(dl_dx=dl_dx, solver="krylov")
    except SolverError as e:
        monitor.backward_errors.append(f"{type(e).__name__}: {e}")
        return None
    monitor.gradients(g)
    return g


def finish(monitor: Monitor, checks: dict[str, tuple[bool, str]], energy_bound: float | None,
           stretch_bounds: tuple[float, float] | None = None, **extra: Any) -> dict:
    """A case's result: the generic metrics, the bounds the tests assert (``energy_bound``;
    ``stretch_bounds`` for the final state where given), the case's physical ``checks``
    (name -> (holds, detail)) and case-specific numbers."""
    out = monitor.metrics()
    out["energy_bound"] = energy_bound
    out["stretch_bounds"] = list(stretch_bounds) if stretch_bounds else None
    out["checks"] = {k: {"ok": bool(ok), "detail": detail} for k, (ok, detail) in checks.items()}
    out.update(extra)
    return out
