"""L-BFGS-B (scipy) on the unit box, with the objective scaled so the first step is sane.

Why the scaling: on its first iteration L-BFGS-B has no curvature yet and tries the projected
point ``P(u0 - g0)`` (Byrd et al. 1995: the Cauchy point with B = I), so the raw gradient's
size sets the first step (a sphere friction gradient of about 20 sends mu to its bound; a Hat
trajectory gradient flings the cloth, and that rollout then crawls at the iteration cap). The
driver minimizes ``c * L(u)`` with ``c = first_step / max|dL/du(u0)|``: the first trial point
moves each coordinate by at most ``first_step`` of its range (default 0.1). ``c`` is fixed
after the first evaluation, the later steps are plain quasi-Newton steps, and the losses
logged are unscaled.
"""

from __future__ import annotations

import numpy as np

from diffcloth_gym.optim.objective import BudgetExhausted, Objective
from diffcloth_gym.optim.runlog import Run, finish, progress


def run_lbfgsb(objective: Objective, u0: np.ndarray, budget: int | None, seed: int = 0, first_step: float = 0.1,
               show_progress: bool = True, options: dict | None = None) -> Run:
    """Minimizes from ``u0`` (unit box) until scipy converges or the step budget runs out."""
    from scipy.optimize import minimize

    objective.budget = budget
    objective.reset_counters()
    scale = [None]

    def fun(u):
        value, grad = objective.unit_value_and_grad(np.clip(u, 0.0, 1.0))
        if scale[0] is None:
            gmax = float(np.max(np.abs(grad)))
            scale[0] = first_step / gmax if gmax > 0 else 1.0
        return scale[0] * value, scale[0] * grad

    stop = "converged"
    with progress(objective, f"L-BFGS-B seed {seed}", show_progress):
        try:
            res = minimize(fun, np.asarray(u0, dtype=np.float64), jac=True, method="L-BFGS-B",
                           bounds=[(0.0, 1.0)] * len(u0),
                           options={"maxiter": 100000, "maxfun": 100000, **(options or {})})
            stop = f"converged: {res.message}"
        except BudgetExhausted:
            stop = "budget"
    run = finish(objective, "L-BFGS-B", seed, stop)
    run.history = [dict(h, scale=scale[0]) for h in run.history]
    return run
