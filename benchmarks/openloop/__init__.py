"""``python -m benchmarks openloop <study>`` (or ``scripts/openloop.py <study>``): open-loop
optimization studies on :mod:`diffcloth_gym.optim`.

Studies: ``table`` (the paper's Tables 2 and 3: every Sec. 6 task, three optimizers, recovered
parameters; ``table --tasks sphere dress`` runs some; resumable, see ``table --help``);
``fig4`` (the paper's Fig. 4: the flying napkin at 48, 75, 147 and 300 DoF, loss vs
simulated steps for L-BFGS-B, CMA-ES and (1+1)-ES, and the speedup of L-BFGS-B against DoF);
writes ``benchmarks/results/openloop.{json,md}``, ``openloop_fig4.png`` and the per-evaluation
log ``out/openloop_fig4.csv``. ``fig4 --help`` lists the options.
"""

from __future__ import annotations

import sys


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] not in ("fig4", "table"):
        print(__doc__.strip(), file=sys.stderr)
        return 2
    if argv[0] == "table":
        from benchmarks.openloop import table

        return table.main(argv[1:]) or 0
    from benchmarks.openloop import fig4

    return fig4.main(argv[1:]) or 0
