"""The Hat workload benchmark (benchmarks.hat_workloads) on a few steps: every workload runs
from its saved policy, the profile's PD iteration count equals the sum of the steps' own
(checked inside the benchmark), and the report's shares are shares."""

import json

from benchmarks import hat_workloads


def test_every_workload_runs_and_its_counts_add_up(tmp_path):
    assert hat_workloads.main(["--starts", "2", "--steps", "6", "--slow", "20", "--out", str(tmp_path)]) == 0
    rows = json.loads((tmp_path / "hat_workloads.json").read_text())["rows"]
    assert [r["workload"] for r in rows] == list(hat_workloads.WORKLOADS)
    for r in rows:
        assert r["members"] == 2 and r["steps"] == 12
        assert r["pd_iters"] >= 1 and r["ms_per_step"] > 0
        for share in ("polish_time_pct", "slow_steps_pct", "slow_iters_pct", "slow_time_pct"):
            assert 0 <= r[share] <= 100
