"""(1+1)-ES with the 1/5th success rule (Rechenberg; Kern et al. 2004), on the unit box."""

from __future__ import annotations

import numpy as np

from diffcloth_gym.optim.objective import BudgetExhausted, Objective
from diffcloth_gym.optim.runlog import Run, finish, progress


def run_one_plus_one(objective: Objective, u0: np.ndarray, budget: int | None, seed: int = 0, sigma0: float = 0.25,
                     min_sigma: float = 1e-9, show_progress: bool = True) -> Run:
    """One parent, one Gaussian child per evaluation (clipped into the box); the child replaces
    the parent if it is no worse. sigma grows by exp(1/3) on success and shrinks by exp(-1/12)
    on failure, which keeps it constant at a success rate of 1/5. Stops at the budget or when
    sigma falls below ``min_sigma``."""
    objective.budget = budget
    objective.reset_counters()
    rng = np.random.default_rng(seed)
    stop = "budget"
    with progress(objective, f"(1+1)-ES seed {seed}", show_progress):
        try:
            x = np.asarray(u0, dtype=np.float64)
            fx = objective.unit_loss(x)
            sigma = sigma0
            while sigma >= min_sigma:
                y = np.clip(x + sigma * rng.standard_normal(x.size), 0.0, 1.0)
                fy = objective.unit_loss(y)
                if fy <= fx:
                    x, fx = y, fy
                    sigma *= np.exp(1.0 / 3.0)
                else:
                    sigma *= np.exp(-1.0 / 12.0)
            stop = "converged: sigma below min_sigma"
        except BudgetExhausted:
            pass
    return finish(objective, "(1+1)-ES", seed, stop)
