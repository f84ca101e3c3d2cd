#!/usr/bin/env python3
"""Open-loop optimization studies (``fig4``: the paper's Fig. 4, the flying napkin): writes
benchmarks/results/openloop.{json,md} and plots (options: ``openloop.py fig4 --help``). The
code is benchmarks/openloop/ on diffcloth_gym.optim."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository root: the benchmarks package
from benchmarks.openloop import main  # noqa: E402

sys.exit(main())
