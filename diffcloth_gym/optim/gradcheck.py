"""Analytic gradient vs central differences, entry by entry, with the contacts that changed
branch between the ``+eps`` and ``-eps`` rollouts: a large error where contacts switched is a
contact event (the loss is not differentiable there at that eps), one where none did is a bug
or a loose forward solve."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from diffcloth_gym.optim.objective import Objective
from diffcloth_gym.optim.parameterization import check_theta

BRANCHES = {-1: "none", 0: "take_off", 1: "stick", 2: "slip"}


@dataclass
class Entry:
    index: int
    name: str
    analytic: float
    numeric: float
    #: |analytic - numeric| / (largest |analytic| entry of the whole gradient).
    error: float
    #: Contacts whose branch differs between the +eps and -eps rollouts, as (step, node_a,
    #: node_b, obstacle, branch at -eps, branch at +eps); -1 node_b / obstacle: none, branch
    #: "none": no contact there.
    switched: list = field(default_factory=list)


@dataclass
class GradcheckReport:
    loss: float
    grad_max: float
    eps: float
    entries: list

    @property
    def max_error(self) -> float:
        return max((e.error for e in self.entries), default=0.0)

    def __str__(self) -> str:
        lines = [f"gradcheck: loss {self.loss:.6g}, max |grad| {self.grad_max:.3g}, eps {self.eps:g}",
                 f"{'entry':>24} {'analytic':>12} {'central':>12} {'error':>9} switched"]
        for e in self.entries:
            lines.append(f"{e.name:>24} {e.analytic:12.5g} {e.numeric:12.5g} {e.error:9.2e} {len(e.switched)}")
            for s in e.switched[:3]:
                step, a, b, o, bm, bp = s
                what = f"obstacle {o}" if o >= 0 else f"node {b}"
                lines.append(f"{'':>24}   step {step}: node {a} / {what}: {BRANCHES[bm]} -> {BRANCHES[bp]}")
        return "\n".join(lines)


def _switched(minus: list[dict], plus: list[dict]) -> list[tuple]:
    out = []
    for step, (m, p) in enumerate(zip(minus, plus)):
        for key in sorted(set(m) | set(p)):
            bm, bp = m.get(key, -1), p.get(key, -1)
            if bm != bp:
                out.append((step, *key, bm, bp))
    return out


def gradcheck(objective: Objective, theta, indices=None, eps: float | np.ndarray = 1e-6) -> GradcheckReport:
    """Compares ``objective``'s gradient at ``theta`` with central differences ``(L(theta + eps
    e_i) - L(theta - eps e_i)) / (2 eps)`` for each index in ``indices`` (default: all), and
    lists the contacts that changed branch between the two rollouts. ``eps`` may be one number
    or one per entry (parameters in different units). The forward must be converged far
    tighter than ``eps`` times the gradient (the objective's default preset, 1e-11, is).
    Runs outside any budget (the counters are restored)."""
    theta = check_theta(objective.param, theta)
    budget, objective.budget = objective.budget, None
    saved = (objective.forward_steps, objective.backward_steps, list(objective.history), objective.best_loss,
             objective.best_theta)
    try:
        loss, grad = objective(theta)
        gmax = float(np.max(np.abs(grad))) or 1.0
        idx = range(objective.param.size) if indices is None else [int(i) for i in indices]
        eps_v = np.broadcast_to(np.asarray(eps, dtype=np.float64), (objective.param.size,))
        entries = []
        for i in idx:
            e = np.zeros_like(theta)
            e[i] = eps_v[i]
            xs_p, br_p = objective.rollout(theta + e, contacts=True)
            xs_m, br_m = objective.rollout(theta - e, contacts=True)
            numeric = (objective.loss_fn(xs_p)[0] - objective.loss_fn(xs_m)[0]) / (2 * eps_v[i])
            entries.append(Entry(i, objective.param.names[i], float(grad[i]), float(numeric),
                                 abs(grad[i] - numeric) / gmax, _switched(br_m, br_p)))
        return GradcheckReport(loss, gmax, float(np.max(eps_v)), entries)
    finally:
        objective.budget = budget
        (objective.forward_steps, objective.backward_steps, objective.history, objective.best_loss,
         objective.best_theta) = saved
