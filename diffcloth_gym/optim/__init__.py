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
(runs, CSV, JSON, progress bars, shared starts), ``gradcheck.py``; the paper's tasks:
``tasks.py`` (the Task record, the flying napkin), ``tasks_ident.py`` (sphere, wind, T-shirt,
flag), ``tasks_design.py`` (dress), ``tasks_dressing.py`` (hat, sock), ``shapes.py`` and
``tasks_meshes.py`` (procedural garment meshes); :data:`TASKS` names them all. Needs the
``optim`` extra (scipy, cma, tqdm) for the drivers, and torch for the hat and sock tasks.
"""

from diffcloth_gym.optim.cmaes import run_cmaes
from diffcloth_gym.optim.forces import NodeForces
from diffcloth_gym.optim.gradcheck import GradcheckReport, gradcheck
from diffcloth_gym.optim.lbfgsb import run_lbfgsb
from diffcloth_gym.optim.losses import (GroupKeypoints, HeightMatch, KeypointDistance, Loss, ShapeMatch, SmoothL1, Sum,
                                       TrajectoryMatch)
from diffcloth_gym.optim.objective import BudgetExhausted, Objective
from diffcloth_gym.optim.one_plus_one import run_one_plus_one
from diffcloth_gym.optim.parameterization import Fixed, Inputs, Parameterization, Stack, from_unit, to_unit
from diffcloth_gym.optim.physical import PhysicalParams
from diffcloth_gym.optim.runlog import Run, initial_guess, write_csv, write_json
from diffcloth_gym.optim.spline import HermiteSpline, hermite_basis
from diffcloth_gym.optim.tasks import Task, flying_napkin, synthesize
from diffcloth_gym.optim.tasks_design import dress
from diffcloth_gym.optim.tasks_dressing import hat, sock
from diffcloth_gym.optim.tasks_ident import flag, sphere, tshirt, wind

DRIVERS = {"L-BFGS-B": run_lbfgsb, "CMA-ES": run_cmaes, "(1+1)-ES": run_one_plus_one}

#: The paper's Sec. 6 tasks (and the wind identification) by name: builders returning a
#: :class:`Task` (keyword arguments shrink them for tests, e.g. ``TASKS["sphere"](steps=60)``).
TASKS = {"sphere": sphere, "wind": wind, "tshirt": tshirt, "flag": flag, "dress": dress, "hat": hat, "sock": sock}

__all__ = [
    "BudgetExhausted", "DRIVERS", "Fixed", "GradcheckReport", "GroupKeypoints", "HeightMatch", "TASKS", "HermiteSpline", "Inputs", "KeypointDistance", "Loss",
    "NodeForces", "Objective", "Parameterization", "PhysicalParams", "Run", "ShapeMatch", "SmoothL1", "Stack",
    "Sum", "Task", "TrajectoryMatch", "dress", "flag", "flying_napkin", "hat", "sock", "sphere", "synthesize",
    "tshirt", "wind", "from_unit", "gradcheck", "hermite_basis",
    "initial_guess", "run_cmaes", "run_lbfgsb", "run_one_plus_one", "to_unit", "write_csv", "write_json",
]
