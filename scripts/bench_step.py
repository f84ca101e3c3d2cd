#!/usr/bin/env python3
"""Forward step benchmark: writes benchmarks/results/step_time.{json,md} (options: --help). The code is benchmarks/step_time.py."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository root: the benchmarks package
from benchmarks.step_time import main  # noqa: E402

sys.exit(main())
