"""SHAC (short-horizon actor-critic) in the training harness, on tiny budgets (FlyingNapkin
4x4): its TD(lambda) targets are the lambda-returns by definition, its windows lower the
training loss on a fixed start and fit the critic, every simulated step and one-step adjoint is
counted, a run resumes bitwise, and the comparison runs it beside APG."""

import json

import numpy as np
import pytest
import torch

import diffcloth_gym  # noqa: F401
from diffcloth_gym.envs.flying_napkin_v0 import TEST_STARTS
from diffcloth_gym.training.shac import SHACTrainer, td_lambda_targets

NAPKIN = {"env_id": "DiffCloth/FlyingNapkin-v0", "env": {"resolution": 4}}
HORIZON = 100
STARTS = list(TEST_STARTS[:2])


def shac_cfg(**kw):
    return {**NAPKIN, "batch": 2, "epochs": 2, "window": 30, "eval_every": 1, "lr": 1e-2,
            "critic_iterations": 4, **kw}


def lambda_return(r, v, gamma, lam, t):
    """The lambda-return by its definition: a (1 - lam) lam^(k-1) mix of the k-step returns,
    the longest (to the window's end) taking the remaining weight lam^(h-t-1)."""
    h = len(r)

    def k_step(k):
        return sum(gamma ** j * r[t + j] for j in range(k)) + gamma ** k * v[t + k - 1]

    n = h - t
    return sum((1 - lam) * lam ** (k - 1) * k_step(k) for k in range(1, n)) + lam ** (n - 1) * k_step(n)


@pytest.mark.parametrize("ends", [False, True])
def test_td_lambda_targets_are_lambda_returns(ends):
    g = torch.Generator().manual_seed(0)
    r, v = torch.randn(6, 3, generator=g, dtype=torch.float64), torch.randn(6, 3, generator=g, dtype=torch.float64)
    got = td_lambda_targets(r, v, 0.9, 0.7, ends)
    v_used = v.clone()
    if ends:
        v_used[-1] = 0.0  # the episode's last state has no future
    for t in range(6):
        torch.testing.assert_close(got[t], lambda_return(r, v_used, 0.9, 0.7, t), rtol=1e-13, atol=1e-13)


def test_shac_windows_lower_the_training_loss_and_fit_the_critic(monkeypatch):
    import diffcloth_gym.training.shac as shac

    monkeypatch.setattr(shac, "epoch_seed", lambda *a: 7)  # the same starts every epoch
    tr = SHACTrainer(shac_cfg(clip_grad_norm=0.0), progress=False, eval_starts=STARTS[:1])
    rows = [tr.run_epoch() for _ in range(3)]
    # 100 steps in windows of 30: 30, 30, 30, 10.
    assert [r["actor_updates"] for r in rows] == [4, 4, 4]
    assert all(np.isfinite(r["grad_norm"]) and r["grad_norm"] > 0 and r["clipped"] == 0 for r in rows)
    assert rows[2]["train_loss"] < rows[0]["train_loss"]
    # Each window's regression lowers the critic's error on its targets.
    assert all(r["critic_loss"] < r["critic_loss_first_pass"] for r in rows)


def test_shac_counts_its_steps_logs_clipping_and_resumes_bitwise(tmp_path):
    cfg = shac_cfg(epochs=3, clip_grad_norm=1e-6)
    full = SHACTrainer(cfg, tmp_path / "full", progress=False, eval_starts=STARTS)
    s = full.train()
    # 3 epochs x 2 members x 100 steps, forward and one-step adjoints; evaluation apart.
    assert s["forward"] == s["attempted"] == s["backward"] == s["paper_steps"] == 3 * 2 * HORIZON
    assert s["eval_steps"] == 4 * len(STARTS) * HORIZON
    assert [r["clipped"] for r in full.train_log.rows()] == ["4", "4", "4"] and s["clipped_epochs"] == 12
    part = SHACTrainer(cfg, tmp_path / "part", progress=False, eval_starts=STARTS)
    part.train(epochs=2)  # "killed" after epoch 2's checkpoint
    resumed = SHACTrainer(cfg, tmp_path / "part", progress=False, eval_starts=STARTS)
    assert resumed.epoch == 2
    r = resumed.train()
    for a, b in [(full.policy, resumed.policy), (full.critic, resumed.critic),
                 (full.target_critic, resumed.target_critic)]:
        for p, q in zip(a.parameters(), b.parameters()):
            assert torch.equal(p, q)
    assert [p["test_loss"] for p in r["curve"]] == [p["test_loss"] for p in s["curve"]]
    assert full.counter.snapshot() == resumed.counter.snapshot()
    assert list((tmp_path / "full" / "tb").glob("events.out.tfevents.*"))  # TensorBoard beside the CSV


def test_bad_window_is_refused():
    tr = SHACTrainer(shac_cfg(window=0), progress=False, eval_starts=STARTS[:1])
    with pytest.raises(ValueError, match="window"):
        tr.run_epoch()


def test_compare_runs_shac_beside_apg(tmp_path):
    from diffcloth_gym.training import compare

    budget = {"name": "tiny", **NAPKIN, "seeds": [0], "methods": ["apg", "shac"], "eval_stride": 10,
              "apg": {"epochs": 1, "batch": 2, "eval_every": 1},
              "shac": {"epochs": 1, "batch": 2, "window": 50, "eval_every": 1, "critic_iterations": 2}}
    compare.run(budget, out=tmp_path, progress=False, gif=False, command="pytest")
    data = json.loads((tmp_path / "hat_controller.json").read_text())
    assert [s["method"] for s in data["runs"]] == ["apg", "shac"]
    assert [s["forward"] for s in data["runs"]] == [2 * HORIZON, 2 * HORIZON]
    assert "APG vs SHAC" in (tmp_path / "hat_controller.md").read_text()
