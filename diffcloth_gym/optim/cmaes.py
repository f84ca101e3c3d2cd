"""CMA-ES (Hansen's ``cma`` package) on the unit box, from the same start as the others."""

from __future__ import annotations

import numpy as np

from diffcloth_gym.optim.objective import BudgetExhausted, Objective
from diffcloth_gym.optim.runlog import Run, finish, progress


def run_cmaes(objective: Objective, u0: np.ndarray, budget: int | None, seed: int = 0, sigma0: float = 0.25,
              popsize: int | None = None, show_progress: bool = True) -> Run:
    """Evaluates ``u0`` (so every method's history starts at the same loss), then runs CMA-ES
    with step size ``sigma0`` (a fraction of each range) and the ``cma`` default population
    ``4 + 3 ln d`` until it stops or the budget runs out (a generation cut short by the budget
    is not told to the strategy). ``cma``'s own seed is ``seed + 1`` (its 0 means random).
    One-dimensional problems (the sphere's mu) run too, without cma's bound-derived std cap."""
    import cma

    objective.budget = budget
    objective.reset_counters()
    opts = {"bounds": [0.0, 1.0], "seed": seed + 1, "verbose": -9, "tolfun": 0.0, "tolfunhist": 0.0,
            "tolx": 1e-14}
    if popsize:
        opts["popsize"] = popsize
    if len(u0) == 1:
        # cma 4.x derives a maximal std from the bounds, and enforcing it in one dimension
        # raises "not yet initialized (dimension needed)" at the first tell (pycma issues 86,
        # 302: 1-D is unsupported): no cap there (sigma0 0.25 of the unit range stays sane).
        opts["maxstd"] = np.inf
    stop = "budget"
    with progress(objective, f"CMA-ES seed {seed}", show_progress):
        try:
            objective.unit_loss(u0)
            es = cma.CMAEvolutionStrategy(np.asarray(u0, dtype=np.float64), sigma0, opts)
            while not es.stop():
                xs = es.ask()
                es.tell(xs, [objective.unit_loss(x) for x in xs])
            stop = f"converged: {es.stop()}"
        except BudgetExhausted:
            pass
    return finish(objective, "CMA-ES", seed, stop)
