"""``python -m benchmarks <study> [options]`` (from the repository root).

Studies: ``accuracy`` (what each accuracy knob costs in time: forward Pareto fronts, the
backward solver table, gradient error vs forward tolerance, time step), ``stability`` (the
hard-case suite; ``--full`` for the full size), ``step_time`` (forward ms/step per solver
setting, and the contact scenes), ``backward_time`` (adjoint ms/step per solver), ``gradient_cost``
(forward + polish + backward ms/step at the envs' accuracy and the gradient's error),
``gradient_horizon`` (over how many contact-rich steps a gradient is still the loss's derivative),
``hat_workloads`` (where Hat-v0's forward time goes under APG, PPO and random actions),
``env_throughput`` (env steps/s single and batched, step_grad cost, frames/s), ``render``
(frames/s of the software renderer; ``render --images`` writes docs/images/) and ``openloop``
(open-loop optimization: ``openloop fig4``, the paper's Fig. 4; results ``openloop.{json,md}``). Each writes
``benchmarks/results/<study>.{json,md}`` (accuracy: ``accuracy_time``); ``<study> --help`` lists
its options.
"""

from __future__ import annotations

import importlib
import sys

STUDIES = {
    "accuracy": "benchmarks.accuracy",
    "stability": "benchmarks.stability",
    "step_time": "benchmarks.step_time",
    "backward_time": "benchmarks.backward_time",
    "gradient_cost": "benchmarks.gradient_cost",
    "gradient_horizon": "benchmarks.gradient_horizon",
    "env_throughput": "benchmarks.env_throughput",
    "render": "benchmarks.render",
    "openloop": "benchmarks.openloop",
    "hat_workloads": "benchmarks.hat_workloads",
}


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] not in STUDIES:
        print(__doc__.strip(), file=sys.stderr)
        return 2
    module = importlib.import_module(STUDIES[argv[0]])
    return module.main(argv[1:]) or 0


if __name__ == "__main__":
    sys.exit(main())
