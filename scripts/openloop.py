#!/usr/bin/env python3
"""Open-loop optimization studies: ``table`` (the paper's Tables 2-3: every Sec. 6 task;
``openloop.py table --tasks sphere dress`` runs some) and ``fig4`` (the paper's Fig. 4, the
flying napkin); they write benchmarks/results/openloop.json, openloop{,_table}.md and plots
(options: ``openloop.py table --help``). The code is benchmarks/openloop/ on
diffcloth_gym.optim."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository root: the benchmarks package
from benchmarks.openloop import main  # noqa: E402

sys.exit(main())
