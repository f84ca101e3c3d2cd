"""Accuracy vs time: what each accuracy knob of the simulator costs (issue 5, item 1).

``python -m benchmarks accuracy [--part forward|backward|gradient|timestep|all]
[--scene wind,slope,hat,hat_contact,sock] [--res 12 24 48] [--quick] [--out DIR]``

Parts (one module each: its settings, rows, plot and report section; every row in the JSON
has a ``part`` field):

1. ``forward``: PD tolerance and iteration-cap sweeps, plain PD vs Anderson; ms/step,
   iterations/step and trajectory error against a tightly converged run; a Pareto plot per scene.
2. ``backward``: the paper's Table 1 with our numbers: direct vs fixed_point vs krylov adjoint
   solves at eps 1e-2 ... 1e-9 on Wind and Slope; time, stage shares, fail %, speedup, gradient
   error against direct; the paper's numbers beside ours.
3. ``gradient``: the gradient error caused by the forward tolerance (each tolerance, and
   the gradient solver preset) against the gradient of a converged trajectory (Hat, Sock, Wind 24x24).
4. ``timestep``: error and time against the time step h for a fixed simulated duration.

Writes ``accuracy_time.{json,md}`` and PNG plots (``accuracy_*.png``) to ``benchmarks/results``
(or ``--out``). A run of some parts keeps the other parts' rows from an earlier run in the same
folder (their own meta is kept in ``meta.parts``). All runs are single-threaded
(``parallel=False``) and time is measured inside Rust (the simulator's profile) where possible.
"""

from benchmarks.accuracy.backward import backward_scene, plot_backward
from benchmarks.accuracy.common import Scene, garment_scene, grid_scene
from benchmarks.accuracy.forward import forward_scene, plot_forward
from benchmarks.accuracy.gradient import gradient_scene, plot_gradient
from benchmarks.accuracy.study import PARTS, Plan, main, make_plan, parse_args, run_part, write_report
from benchmarks.accuracy.timestep import plot_timestep, timestep_scene

__all__ = ["PARTS", "Plan", "Scene", "backward_scene", "forward_scene", "garment_scene", "gradient_scene",
           "grid_scene", "main", "make_plan", "parse_args", "plot_backward", "plot_forward", "plot_gradient",
           "plot_timestep", "run_part", "timestep_scene", "write_report"]
