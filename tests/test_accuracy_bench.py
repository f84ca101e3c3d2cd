"""The accuracy-vs-time study (benchmarks.accuracy) on Wind 12x12 with a few steps.

Checks facts that must hold whatever the machine's speed (no wall-clock assertions): tighter
forward tolerances give smaller trajectory errors, Anderson needs fewer iterations than plain
PD, tighter adjoint tolerances give gradients closer to the direct solve's, converged
recording gives the converged gradient, smaller time steps give smaller errors, and the report
files hold every part.
"""

import json

import pytest

from benchmarks import accuracy, results_io
from diffcloth_gym.scenes import contact_free, load_scene


@pytest.fixture(scope="module")
def rows():
    """All four parts on Wind 12x12, shortened (about 10 s in all)."""
    forward = accuracy.forward_scene(accuracy.grid_scene("wind", 12, 12), tolerances=(1e-3, 1e-6, 1e-10), caps=(10,))
    backward = accuracy.backward_scene(accuracy.grid_scene("wind", 12, 8, v_sigma=0.1), eps_list=(1e-2, 1e-4, 1e-6, 1e-8))
    scene = accuracy.Scene("wind12x12", contact_free(load_scene("wind", rows=12, cols=12)), 15)
    gradient = accuracy.gradient_scene(scene, full=False)
    timestep = accuracy.timestep_scene(accuracy.grid_scene("wind", 12, 0), hs=(1 / 25, 1 / 50, 1 / 100), h_ref=1 / 400,
                                       duration=0.2, tolerances=(1e-10,))
    return {"forward": forward, "backward": backward, "gradient": gradient, "timestep": timestep}


def by(rows, **match):
    return [r for r in rows if all(r.get(k) == v for k, v in match.items())]


def test_forward_error_falls_with_tolerance_and_anderson_saves_iterations(rows):
    fwd = rows["forward"]
    for solver in ("plain", "AA", "AA+polish"):
        loose, tight = (by(fwd, solver=solver, sweep="tolerance", tolerance=t)[0] for t in (1e-3, 1e-10))
        assert tight["traj_rel_err"] < loose["traj_rel_err"], solver
        assert tight["traj_rel_err"] < 1e-4
    for tol in (1e-6, 1e-10):
        plain, aa = (by(fwd, solver=s, sweep="tolerance", tolerance=tol)[0] for s in ("plain", "AA"))
        assert aa["iters_per_step"] < plain["iters_per_step"], tol
    # The polish rows did polish (Newton steps once the update fell below 1e-5), and where it
    # did it took fewer PD iterations than Anderson alone at that tolerance.
    polished, aa = (by(fwd, solver=s, sweep="tolerance", tolerance=1e-10)[0] for s in ("AA+polish", "AA"))
    assert polished["newton_steps_per_step"] > 0 and aa["newton_steps_per_step"] == 0
    assert polished["iters_per_step"] < aa["iters_per_step"]
    assert by(fwd, sweep="reference")[0]["unconverged_pct"] == 0
    # A run 10x tighter than the reference agrees with it better than any swept setting
    # without the polish (the polish converges past its tolerance); the polished one at 1e-13
    # lands as close (the same minimum: the reference's own error dominates both).
    floor = by(fwd, sweep="reference_check")[0]["traj_rel_err"]
    assert floor < min(r["traj_rel_err"] for r in fwd if r["sweep"] == "tolerance" and r["polish"] == "none")
    assert by(fwd, sweep="reference_check_polished")[0]["traj_rel_err"] < 2 * floor
    # Tolerance 0: every step runs exactly its cap.
    for r in by(fwd, sweep="cap"):
        assert r["iters_per_step"] == r["max_iterations"]
    assert any(r["pareto"] for r in fwd)


def test_adjoint_error_falls_with_eps(rows):
    bwd = rows["backward"]
    direct = by(bwd, solver="direct")[0]
    assert direct["all_rel_err"] == 0 and direct["speedup_vs_direct"] == 1
    for solver in ("krylov", "fixed_point"):
        errs = [by(bwd, solver=solver, eps=eps)[0]["all_rel_err"] for eps in (1e-2, 1e-4, 1e-6, 1e-8)]
        assert all(b < a for a, b in zip(errs, errs[1:])), (solver, errs)
        assert errs[-1] < 1e-5
        assert by(bwd, solver=solver, eps=1e-8)[0]["v0_cos"] > 0.999999
    for r in bwd:
        assert abs(r["dp_pct"] + r["dr_pct"] + r["solve_pct"] + r["other_pct"] - 100) < 1e-6


def test_polished_recording_gives_the_converged_gradient(rows):
    grad = rows["gradient"]
    polished = [r for r in grad if r["polish"]]
    assert polished and all(r["v0_rel_err"] < 1e-4 and r["targets_rel_err"] < 1e-4 and not r["warned"] for r in polished)
    loose = by(grad, setting="AA 1e-04, no polish")[0]
    # Recorded steps stopped at 1e-4 are above the adjoint's trusted residual: said, not hidden.
    assert loose["warned"] and loose["v0_rel_err"] > polished[0]["v0_rel_err"]


def test_smaller_time_step_smaller_error(rows):
    errs = [r["rel_err"] for r in sorted(rows["timestep"], key=lambda r: -r["h"])]
    assert all(b < a for a, b in zip(errs, errs[1:])), errs


def test_report_has_every_part(rows, tmp_path):
    all_rows = [r for part in accuracy.PARTS for r in rows[part]]
    for part in accuracy.PARTS:
        {"forward": accuracy.plot_forward, "backward": accuracy.plot_backward, "gradient": accuracy.plot_gradient,
         "timestep": accuracy.plot_timestep}[part](rows[part], tmp_path)
    json_path, md_path = accuracy.write_report(all_rows, results_io.meta({"command": "pytest"}), tmp_path)
    data = json.loads(json_path.read_text())
    assert {r["part"] for r in data["rows"]} == set(accuracy.PARTS)
    md = md_path.read_text()
    for heading in ("## 1. Forward", "## 2. Backward", "## 3. Gradient", "## 4. Time step", "paper ms/step"):
        assert heading in md
    # One plot each: forward (per scene), backward (per test), gradient, timestep.
    assert len(list(tmp_path.glob("accuracy_*.png"))) == 4


def test_cli_arguments():
    args = accuracy.parse_args(["--scene", "wind,hat", "--scene", "slope", "--part", "forward", "--quick"])
    assert args.scene == ["wind", "hat", "slope"] and args.part == ["forward"] and args.res == [12]
    plan = accuracy.make_plan(args.scene, args.res, args.quick)
    assert [s.label for s in plan.forward] == ["wind12x12", "hat_nocontact", "slope12x12"]
    with pytest.raises(SystemExit):
        accuracy.parse_args(["--scene", "bogus"])
