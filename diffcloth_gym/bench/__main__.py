"""``python -m diffcloth_gym.bench <study> [options]``.

Studies: ``accuracy`` (what each accuracy knob costs in time: forward Pareto fronts, the
backward solver table, gradient error vs forward tolerance, time step) and ``stability``
(the hard-case suite at full size). Each writes ``benchmarks/results/<study>.{json,md}``.
"""

from __future__ import annotations

import importlib
import sys

STUDIES = {"accuracy": "diffcloth_gym.bench.accuracy", "stability": "diffcloth_gym.bench.stability"}


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] not in STUDIES:
        print(__doc__.strip(), file=sys.stderr)
        return 2
    module = importlib.import_module(STUDIES[argv[0]])
    return module.main(argv[1:]) or 0


if __name__ == "__main__":
    sys.exit(main())
