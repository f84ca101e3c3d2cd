"""The gradient-horizon study (benchmarks.gradient_horizon) on the 24x24 sphere drop, 10 steps:
with friction and self-collision on and the cloth pushing on the sphere, the analytic
gradient is the loss's local derivative (central differences at 1e-6 agree) and a 1e-12
rollout reproduces the 1e-13 one's gradient; the report holds every column."""

import json

from benchmarks import gradient_horizon


def test_a_short_contact_rich_horizon_has_an_exact_reproducible_gradient(tmp_path):
    row = gradient_horizon.measure("sphere24x24", "full", 10, "env")
    assert row["pushing_steps"] >= 5, row
    assert row["fd_err_1e-06"] < 1e-3, row
    assert row["repro_err"] < 1e-6, row
    gradient_horizon.main(["--scenes", "sphere24x24", "--horizons", "5", "--variants", "mu0", "--out", str(tmp_path)])
    saved = json.loads((tmp_path / "gradient_horizon.json").read_text())
    rows = saved["rows"]
    assert rows and {"grad_max", "repro_err", "fd_err_1e-06", "fd_err_0.0001"} <= set(rows[0]), rows


def test_the_sock_scene_has_an_exact_gradient_before_it_reaches_the_foot():
    """Sock-v0's scene in the study (its effectors drag it towards the foot; the first push on
    the foot comes after step 100): over 25 steps its gradient is the loss's derivative."""
    row = gradient_horizon.measure("sock", "full", 25)
    assert row["pushing_steps"] == 0, row
    assert row["fd_err_1e-06"] < 1e-3 and row["fd_err_0.0001"] < 1e-4, row
    assert row["repro_err"] < 1e-5, row
