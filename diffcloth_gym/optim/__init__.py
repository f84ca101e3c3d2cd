"""Open-loop optimization on the simulator: parameterizations, losses, one objective with a
step counter, drivers (L-BFGS-B, CMA-ES, (1+1)-ES) and a gradient check.

    from diffcloth_gym import Simulator
    from diffcloth_gym.optim import Objective, PhysicalParams, TrajectoryMatch, run_lbfgsb

    sim = Simulator.from_config("sphere")
    param = PhysicalParams(sim, {"mu_obstacles[0]": (0.0, 1.0)})
    obj = Objective(sim, param, TrajectoryMatch(observed), steps=len(observed))
    run = run_lbfgsb(obj, obj.to_unit([0.6]), budget=20_000)
    run.best_theta, run.best_loss, run.steps_used

Files: ``parameterization.py`` (the protocol, the unit box, :class:`Stack`), ``spline.py``,
``forces.py``, ``physical.py`` (the parameterizations), ``losses.py``, ``objective.py`` (and the
step-counting rule), ``lbfgsb.py``, ``cmaes.py``, ``one_plus_one.py`` (drivers), ``runlog.py``
(runs, CSV, JSON, progress bars, shared starts), ``gradcheck.py``, ``tasks.py``. Needs the
``optim`` extra (scipy, cma, tqdm) for the drivers.
"""

from diffcloth_gym.optim.cmaes import run_cmaes
from diffcloth_gym.optim.forces import NodeForces
from diffcloth_gym.optim.gradcheck import GradcheckReport, gradcheck
from diffcloth_gym.optim.lbfgsb import run_lbfgsb
from diffcloth_gym.optim.losses import KeypointDistance, Loss, ShapeMatch, SmoothL1, Sum, TrajectoryMatch
from diffcloth_gym.optim.objective import BudgetExhausted, Objective
from diffcloth_gym.optim.one_plus_one import run_one_plus_one
from diffcloth_gym.optim.parameterization import Inputs, Parameterization, Stack, from_unit, to_unit
from diffcloth_gym.optim.physical import PhysicalParams
from diffcloth_gym.optim.runlog import Run, initial_guess, write_csv, write_json
from diffcloth_gym.optim.spline import HermiteSpline, hermite_basis
from diffcloth_gym.optim.tasks import Task, flying_napkin

DRIVERS = {"L-BFGS-B": run_lbfgsb, "CMA-ES": run_cmaes, "(1+1)-ES": run_one_plus_one}

__all__ = [
    "BudgetExhausted", "DRIVERS", "GradcheckReport", "HermiteSpline", "Inputs", "KeypointDistance", "Loss",
    "NodeForces", "Objective", "Parameterization", "PhysicalParams", "Run", "ShapeMatch", "SmoothL1", "Stack",
    "Sum", "Task", "TrajectoryMatch", "flying_napkin", "from_unit", "gradcheck", "hermite_basis",
    "initial_guess", "run_cmaes", "run_lbfgsb", "run_one_plus_one", "to_unit", "write_csv", "write_json",
]
