"""The training harness on tiny budgets (FlyingNapkin 4x4: cheap; the harness is env-generic and
the Hat uses the same code): an APG epoch lowers the training loss on a fixed start, PPO runs end
to end on the batched vector env, evaluation on TEST_STARTS is bitwise repeatable, the time-step
count equals the steps simulated, and a run killed after a checkpoint resumes bitwise."""

import csv

import numpy as np
import pytest
import torch

import diffcloth_gym  # noqa: F401
from diffcloth_gym.envs.flying_napkin_v0 import TEST_STARTS
from diffcloth_gym.training.apg import APGTrainer
from diffcloth_gym.training.evaluate import evaluate
from diffcloth_gym.training.policy import MLPPolicy

pytest.importorskip("stable_baselines3")

NAPKIN = {"env_id": "DiffCloth/FlyingNapkin-v0", "env": {"resolution": 4}}
HORIZON = 100
STARTS = list(TEST_STARTS[:4])


def apg_cfg(**kw):
    return {**NAPKIN, "batch": 2, "epochs": 2, "eval_every": 1, "lr": 1e-2, **kw}


def ppo_cfg(**kw):
    return {**NAPKIN, "num_envs": 2, "n_steps": HORIZON, "batch_size": 100, "n_epochs": 2,
            "timesteps": 400, "eval_every": 200, **kw}


def test_an_apg_epoch_lowers_the_training_loss_on_a_fixed_start(monkeypatch):
    import diffcloth_gym.training.apg as apg

    monkeypatch.setattr(apg, "epoch_seed", lambda *a: 7)  # the same starts every epoch
    tr = APGTrainer(apg_cfg(clip_grad_norm=0.0), progress=False, eval_starts=STARTS[:1])
    first = tr.run_epoch()
    second = tr.run_epoch()
    assert np.isfinite(first["grad_norm"]) and first["grad_norm"] > 0 and not first["clipped"]
    assert second["train_loss"] < first["train_loss"]
    # Per-member gradients add up to the batch gradient (the loss is the batch mean).
    assert first["member_grad_norm_mean"] > 0 and first["grad_variance"] >= 0


def test_apg_step_count_equals_the_steps_simulated_and_clipping_is_logged(tmp_path):
    tr = APGTrainer(apg_cfg(clip_grad_norm=1e-6, window=30), tmp_path, progress=False, eval_starts=STARTS)
    s = tr.train()
    # 2 epochs x 2 members x 100 steps, forward and one-step adjoints; evaluation apart.
    assert s["forward"] == s["attempted"] == 2 * 2 * HORIZON == s["backward"]
    assert s["paper_steps"] == 2 * HORIZON
    assert s["eval_steps"] == 3 * len(STARTS) * HORIZON  # at epochs 0, 1, 2
    assert sum(tr.engine.batch.step_counts()) == 2 * HORIZON  # the last epoch's, as counted
    rows = tr.train_log.rows()
    assert [r["clipped"] for r in rows] == ["True", "True"] and s["clipped_epochs"] == 2


def test_evaluation_on_test_starts_is_bitwise_deterministic():
    policy = MLPPolicy(96, 48, seed=3, last_layer_scale=1.0)
    a = evaluate(policy, NAPKIN["env_id"], STARTS, NAPKIN["env"])
    b = evaluate(policy, NAPKIN["env_id"], STARTS, NAPKIN["env"])
    assert a.loss.tobytes() == b.loss.tobytes() and a.final_positions.tobytes() == b.final_positions.tobytes()
    assert a.steps == len(STARTS) * HORIZON and len(a.per_start()) == len(STARTS)
    assert set(a.terms) == {"distance"} and a.success.dtype == bool
    # Default starts: every TEST_STARTS.
    assert len(evaluate(policy, NAPKIN["env_id"], env_kwargs=NAPKIN["env"]).starts) == len(TEST_STARTS)


def test_apg_resume_continues_bitwise(tmp_path):
    full = APGTrainer(apg_cfg(epochs=3), tmp_path / "full", progress=False, eval_starts=STARTS[:2])
    full.train()
    part = APGTrainer(apg_cfg(epochs=3), tmp_path / "part", progress=False, eval_starts=STARTS[:2])
    part.train(epochs=2)  # "killed" after epoch 2's checkpoint
    resumed = APGTrainer(apg_cfg(epochs=3), tmp_path / "part", progress=False, eval_starts=STARTS[:2])
    assert resumed.epoch == 2
    resumed.train()
    for p, q in zip(full.policy.parameters(), resumed.policy.parameters()):
        assert torch.equal(p, q)
    strip = lambda c: [{k: v for k, v in p.items() if k != "train_s"} for p in c]  # noqa: E731
    assert strip(full.curve) == strip(resumed.curve)
    assert full.counter.snapshot() == resumed.counter.snapshot()
    assert len(resumed.train_log.rows()) == 3


def test_ppo_runs_end_to_end_counts_its_steps_and_resumes_bitwise(tmp_path):
    from diffcloth_gym.training.ppo import PPOTrainer

    full = PPOTrainer(ppo_cfg(), tmp_path / "full", progress=False, eval_starts=STARTS)
    s = full.train()
    assert s["num_timesteps"] == 400 == s["forward"] == s["attempted"] and s["backward"] == 0
    assert [p["steps"] for p in s["curve"]] == [0, 200, 400]
    assert all(np.isfinite(p["test_loss"]) for p in s["curve"])
    assert (tmp_path / "full" / "sb3" / "progress.csv").exists()
    # TensorBoard too (scripts/_setup.sh installs it).
    assert list((tmp_path / "full" / "sb3").glob("events.out.tfevents.*"))
    part = PPOTrainer(ppo_cfg(), tmp_path / "part", progress=False, eval_starts=STARTS)
    part.train(timesteps=200)
    resumed = PPOTrainer(ppo_cfg(), tmp_path / "part", progress=False, eval_starts=STARTS)
    assert resumed.model.num_timesteps == 200
    r = resumed.train()
    assert [p["test_loss"] for p in r["curve"]] == [p["test_loss"] for p in s["curve"]]
    assert r["forward"] == s["forward"]
    for p, q in zip(full.model.policy.parameters(), resumed.model.policy.parameters()):
        assert torch.equal(p, q)
    # SB3's log keeps the first part's rows (its CSV writer truncates the file it opens).
    logged = {run: _sb3_log(tmp_path / run) for run in ("full", "part")}
    assert [row["time/total_timesteps"] for row in logged["part"]] == ["200", "400"]
    assert [row["rollout/ep_rew_mean"] for row in logged["part"]] == [row["rollout/ep_rew_mean"] for row in logged["full"]]


def _sb3_log(run_dir):
    with (run_dir / "sb3" / "progress.csv").open(newline="") as f:
        return list(csv.DictReader(f))


def test_ppo_killed_between_evaluations_resumes_bitwise_and_a_late_run_does_not_start(tmp_path):
    import time

    from diffcloth_gym.training.ppo import PPOTrainer

    cfg = ppo_cfg(eval_every=400)  # two rollouts of 200 steps per evaluation
    full = PPOTrainer(cfg, tmp_path / "full", progress=False, eval_starts=STARTS[:1])
    s = full.train()
    part = PPOTrainer(cfg, tmp_path / "part", progress=False, eval_starts=STARTS[:1])
    p = part.train(max_rollouts=1)  # "killed" after the first rollout's checkpoint, before an evaluation
    assert p["num_timesteps"] == 200 and [q["steps"] for q in p["curve"]] == [0] and not p["complete"]
    # As if killed between the second rollout's log and its checkpoint: the resume redoes it.
    rows = _sb3_log(tmp_path / "part")
    assert [row["time/total_timesteps"] for row in rows] == ["200"]
    with (tmp_path / "part" / "sb3" / "progress.csv").open("a", newline="") as f:
        csv.DictWriter(f, fieldnames=list(rows[0])).writerow({**rows[0], "time/total_timesteps": "400"})
    resumed = PPOTrainer(cfg, tmp_path / "part", progress=False, eval_starts=STARTS[:1])
    assert resumed.model.num_timesteps == 200
    r = resumed.train()
    assert [row["time/total_timesteps"] for row in _sb3_log(tmp_path / "part")] == ["200", "400"]
    assert [q["steps"] for q in r["curve"]] == [0, 400]
    assert [q["test_loss"] for q in r["curve"]] == [q["test_loss"] for q in s["curve"]]
    for a, b in zip(full.model.policy.parameters(), resumed.model.policy.parameters()):
        assert torch.equal(a, b)
    late = PPOTrainer(cfg, tmp_path / "late", progress=False, eval_starts=STARTS[:1])
    summary = late.train(deadline=time.time() - 1)
    assert summary["curve"] == [] and summary["final_test_loss"] is None and summary["forward"] == 0
    late_apg = APGTrainer(apg_cfg(), tmp_path / "late_apg", progress=False, eval_starts=STARTS[:1])
    assert late_apg.train(deadline=time.time() - 1)["curve"] == []
    # A run that did not start leaves no log files behind (no empty TensorBoard events).
    for run in ("late", "late_apg"):
        assert [f for f in (tmp_path / run).rglob("*") if f.is_file() and f.name.startswith("events.")] == []
    assert list((tmp_path / "part" / "sb3").glob("events.*")) and list((tmp_path / "full" / "sb3").glob("events.*"))


def test_a_run_is_not_resumed_under_other_solver_settings(tmp_path, monkeypatch):
    from diffcloth_gym.envs.flying_napkin_v0 import FlyingNapkinTask

    APGTrainer(apg_cfg(epochs=1), tmp_path, progress=False, eval_starts=STARTS[:1]).train()
    # Same run config, but the env now steps with another polish: its remaining epochs would be
    # another experiment.
    monkeypatch.setattr(FlyingNapkinTask, "solver_defaults", {"polish": "newton"})
    with pytest.raises(ValueError, match="other solver settings.*polish"):
        APGTrainer(apg_cfg(epochs=1), tmp_path, progress=False, eval_starts=STARTS[:1])
    monkeypatch.undo()
    assert APGTrainer(apg_cfg(epochs=1), tmp_path, progress=False, eval_starts=STARTS[:1]).epoch == 1


def test_a_run_is_not_resumed_under_other_dynamics(tmp_path, monkeypatch):
    """Same settings and scene, but the steps or the loss come out different (another build of
    the simulator, an edited task): the dynamics probe's hash refuses the resume."""
    from diffcloth_gym.envs.flying_napkin_v0 import FlyingNapkinTask

    APGTrainer(apg_cfg(epochs=1), tmp_path, progress=False, eval_starts=STARTS[:1]).train()
    loss_terms = FlyingNapkinTask.loss_terms
    monkeypatch.setattr(FlyingNapkinTask, "loss_terms",
                        lambda self, *a: {k: 2 * t for k, t in loss_terms(self, *a).items()})
    with pytest.raises(ValueError, match="other dynamics"):
        APGTrainer(apg_cfg(epochs=1), tmp_path, progress=False, eval_starts=STARTS[:1])
    monkeypatch.undo()
    assert APGTrainer(apg_cfg(epochs=1), tmp_path, progress=False, eval_starts=STARTS[:1]).epoch == 1


def test_compare_writes_results_and_marks_a_stopped_run_partial(tmp_path):
    import json
    import re

    from diffcloth_gym.training import compare

    budget = {"name": "tiny", **NAPKIN, "seeds": [0], "methods": ["apg", "ppo"], "eval_stride": 10,
              "gif_starts_stride": 10, "gif_frame_every": 50,
              "apg": {"epochs": 1, "batch": 2, "eval_every": 1},
              "ppo": {"num_envs": 2, "n_steps": HORIZON, "batch_size": 100, "n_epochs": 1, "timesteps": 200,
                      "eval_every": 200}}
    r = compare.run(budget, out=tmp_path, progress=False, command="pytest")
    for ext in ("json", "md", "png", "gif"):
        assert (tmp_path / f"hat_controller.{ext}").stat().st_size > 0
    data = json.loads((tmp_path / "hat_controller.json").read_text())
    assert not data["partial"] and len(data["test_starts"]) == 2
    assert [s["forward"] for s in data["runs"]] == [2 * HORIZON, 200]
    assert data["runs"][0]["reach_1.1x_apg"] is not None  # APG reaches its own final loss
    # The build it ran on: a commit (in a git checkout, as here and in CI) or said unknown.
    assert re.fullmatch(r"[0-9a-f]{12}(-dirty)?|unknown \(not a git checkout\)", data["build"]), data["build"]
    # A deadline already passed: nothing trains, the longer budget is partial, and says so.
    # Seed 1 has no checkpoint: it does not start (not even its first evaluation).
    longer = {**budget, "seeds": [0, 1], "apg": {**budget["apg"], "epochs": 3}}
    r = compare.run(longer, out=tmp_path, progress=False, max_minutes=0, gif=False, command="pytest",
                    resume_command="resume-here")
    md = (tmp_path / "hat_controller.md").read_text()
    assert r["partial"] and "PARTIAL" in md and "Resume with `resume-here`" in md
    assert [s["curve"] == [] for s in r["runs"]] == [False, False, True, True]
    assert md.count("| not started |") == 2 and r["per_method"]["apg"]["seeds"] == 2


def test_compare_reports_the_ratio_in_both_counts_and_the_evaluations_resolution():
    """APG reaches 1.1x its final loss at 80,000 counted steps (4,000 in the paper's count, one
    rollout of 20 per epoch) and PPO at 128,000: 1.6x counted, 32x the paper's way."""
    from diffcloth_gym.training import compare

    def run(method, points, **kw):
        curve = [{"steps": s, "paper_steps": p, "test_loss": loss} for s, p, loss in points]
        return {"method": method, "seed": 0, "curve": curve, "final_test_loss": curve[-1]["test_loss"],
                "success_rate": 0.1, "complete": True, "forward": curve[-1]["steps"],
                "paper_steps": curve[-1]["paper_steps"], "backward": 0, "train_s": 1.0, "eval_s": 1.0, **kw}

    apg = run("apg", [(0, 0, 1800.0), (40_000, 2_000, 1300.0), (80_000, 4_000, 1100.0)])
    ppo = run("ppo", [(0, 0, 1850.0), (64_000, 64_000, 1500.0), (128_000, 128_000, 1200.0)])
    budget = {**NAPKIN, "eval_stride": 10}
    r = compare.summarize(budget, "tiny", [apg, ppo], [0], ["apg", "ppo"])
    assert r["target_loss_1.1x_apg"] == pytest.approx(1210.0)
    assert r["ppo_over_apg_steps_to_target"] == pytest.approx(1.6)
    assert r["ppo_over_apg_paper_steps_to_target"] == pytest.approx(32.0)
    assert [m["eval_interval"] for m in r["per_method"].values()] == [40_000, 64_000]
    md = compare.markdown({**r, "wall_s": 1.0, "command": "scripts/hat_full_run", "build": "0123abcd"}, "x")
    assert "Command: `scripts/hat_full_run` (code and simulator: git 0123abcd)" in md
    assert "| 80,000 (4,000) |" in md and "| 128,000 |" in md
    assert "1.6x counted, 32.0x in the paper's count" in md and "every 40,000 (APG), 64,000 (PPO)" in md
    # PPO not there yet in a partial run: said so, not as a missed target.
    short = run("ppo", [(0, 0, 1850.0), (64_000, 64_000, 1500.0)], complete=False)
    md = compare.markdown({**compare.summarize(budget, "tiny", [apg, short], [0], ["apg", "ppo"]), "wall_s": 1.0}, "x")
    assert "n/a (a method did not reach it yet: the run is partial)" in md and "| not reached |" in md
