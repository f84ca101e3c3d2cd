#!/usr/bin/env python3
"""Backward benchmark (paper Table 1): writes benchmarks/results/backward_time.{json,md} (options: --help). The code is benchmarks/backward_time.py."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository root: the benchmarks package
from benchmarks.backward_time import main  # noqa: E402

sys.exit(main())
