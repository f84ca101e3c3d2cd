"""Hard-case numerical stability suite (issue 5): the cases as data plus a runner.

Each case is one function ``case_<name>(size, workdir, **variant) -> dict`` (registered in
:data:`CASES`, with variants such as the time step or mu bound) that builds its scene from a
dict config, runs it forward (and backward where it says) and returns the metrics of
:class:`Monitor`, the bounds it is held to and its own physical checks. ``size`` is ``"ci"``
(reduced: seconds) or ``"full"`` (the issue's sizes). ``tests/stability`` asserts on the
returned dicts; ``python -m benchmarks stability [--full]`` writes them to
``benchmarks/results/stability.{json,md}``.

Generic metrics (asserted by the tests for every case):

- ``max_penetration_m``: the deepest any node got *inside* an obstacle, ``max(-d)`` over steps,
  nodes and obstacles (``d`` the signed distance, positive outside). The simulator keeps nodes at
  ``contact.thickness`` outside; the thickness is the tolerance, so a node may intrude into that
  layer but must not cross the surface: allowed :data:`PENETRATION_SLACK_M` beyond it.
- ``max_layer_intrusion_m``: how deep a node got into the thickness layer, ``max(thickness - d)``.
  The contact law holds at the converged PD fixed point, with the contact frames frozen at the
  start of the step; nodes intrude by about 200x the solver tolerance (measured: 2.4e-6 m at the
  default 1e-8, 2.5e-8 m at 1e-10) and, on concave obstacles, by the curvature error
  ``(tangential travel)^2 / (2 R)`` of a step. Allowed: :data:`LAYER_FRACTION` of the thickness.
- ``min_self_distance_m``: the smallest distance between two nodes that share no triangle (the
  pairs the simulator's self-collision considers), against ``self_radius_m``. A pair's normal is
  its separation, so a frozen normal never lets a single pair close further; allowed:
  :data:`SELF_FRACTION` of the radius.
- ``max_energy_ratio``: ``max_t E(t) / E(0)`` of the mechanical energy (kinetic + gravitational
  + elastic) with the gravitational potential measured from the lowest node height of the run
  (so ``E >= 0``). Implicit Euler dissipates, and static obstacles and fixed attachments do no
  work: unforced cases stay below ``energy_bound`` (forced cases report ``None``).
- ``nan_count``: non-finite entries over all states and gradients, plus ``diverged``: the
  simulator's :class:`~diffcloth_gym.errors.DivergedError`, if a step produced one. Both must be
  0 / ``None``.
- ``backward_errors``: ``backward()`` calls that raised a
  :class:`~diffcloth_gym.errors.SolverError` (must be 0).
- ``fallbacks``: Krylov backward solves that fell back to the direct solver (reported),
  ``grad_warnings``: number of ``backward()`` warnings (reported), ``unconverged_steps`` (steps
  stopped at the iteration cap; their ``ConvergenceWarning`` is counted, not printed).

Case-specific physical facts are in ``checks`` (name -> ``{"ok", "detail"}``); known simulator
bugs a case reveals are in :data:`KNOWN_ISSUES` with their reproducers (the tests mark exactly
those assertions as strict expected failures).
"""

from benchmarks.stability.checks import ISSUES, KNOWN_ISSUES, evaluate, known_issue
from benchmarks.stability.harness import SIZES
from benchmarks.stability.metrics import Monitor
from benchmarks.stability.runner import CASES, Case, main, run_case

__all__ = ["CASES", "Case", "ISSUES", "KNOWN_ISSUES", "SIZES", "Monitor", "evaluate", "known_issue", "main", "run_case"]
