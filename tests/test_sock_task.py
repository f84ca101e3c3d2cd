"""Sock-v0's task (diffcloth_gym/envs/sock_v0.py): shapes, the keypoint loss at its goals,
gradients, starts outside the foot and leg, a short rollout, bad start specs."""

import warnings

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from diffcloth_gym import ConvergenceWarning, Simulator, load_scene  # noqa: E402
from diffcloth_gym.envs.sock_v0 import KEYPOINT_NAMES, TEST_STARTS, SockTask  # noqa: E402
from diffcloth_gym.errors import ConfigError, InputError  # noqa: E402

F64 = torch.float64


@pytest.fixture(scope="module")
def scene():
    return load_scene("sock")


@pytest.fixture(scope="module")
def sim(scene):
    return Simulator.from_config(scene)


@pytest.fixture(scope="module")
def task(scene, sim):
    return SockTask(scene, sim.rest_positions, sim.handles, SockTask.default_config())


def batch(a):
    return torch.as_tensor(np.asarray(a), dtype=F64)[None]


def test_dimensions_and_dtypes(task, sim):
    n = sim.num_nodes
    assert (task.horizon, task.action_dim, task.action_bound) == (400, 12, 1.0)
    assert task.obs_dim == 3 * n + 36 + 3 + 3 + 3 + 12 == 3189
    assert task.hook_step == 200
    s = task.start(TEST_STARTS[0])
    assert s.x.shape == s.v.shape == (n, 3) and s.control.shape == (4, 3)
    x, v, c = batch(s.x).repeat(2, 1, 1), batch(s.v).repeat(2, 1, 1), batch(s.control).repeat(2, 1, 1)
    obs = task.observe(x, v, c)
    assert obs.shape == (2, task.obs_dim) and obs.dtype == F64
    c2, drive = task.drive(c, torch.ones(2, 12, dtype=F64))
    assert c2.shape == (2, 4, 3) and drive.forces is None
    assert torch.allclose(drive.targets - c, torch.full_like(c, task.action_scale))
    terms = task.loss_terms(x, v, c, 1)
    assert set(terms) == set(task.term_names) == {"hook", "wear"}
    assert all(t.shape == (2,) and t.dtype == F64 for t in terms.values())
    ok = task.success(x, v, c)
    assert ok.shape == (2,) and ok.dtype == torch.bool and not ok.any()


def test_keypoint_groups_follow_the_geometric_rule(task):
    """Wear groups are the nodes nearest to their foot landmarks on the worn sock; the hook stage
    reuses the four opening groups, which lie on the opening rim (the handles' ring)."""
    assert task.groups.shape == (12, 3)
    worn = task.worn
    for i, name in enumerate(KEYPOINT_NAMES[4:]):
        d = np.linalg.norm(worn - task.landmarks[i], axis=1)
        assert set(task.groups[4 + i]) == set(np.argsort(d)[:3]), name
    rim_y = worn[task.handles, 1].max()
    for i in range(4):
        assert np.all(np.abs(worn[task.groups[i], 1] - rim_y) < 1e-9), KEYPOINT_NAMES[i]
    assert 0 in task.groups[KEYPOINT_NAMES.index("toe")]          # the sock's toe tip node
    assert abs(task.clearance - 0.1) < 1e-9


def test_loss_is_zero_at_the_goals(task):
    worn = batch(task.worn)
    zero = torch.zeros_like(worn)
    c = worn[:, task.handles]
    # Worn: every wear keypoint on target, success.
    assert task.keypoint_distances(worn)[0, 4:].abs().max() < 1e-12
    assert task.loss_terms(worn, zero, c, task.horizon)["wear"].abs().max() < 1e-12
    assert task.success(worn, zero, c).all()
    # Hooked: move each opening group rigidly onto its hook target.
    hooked = worn.clone()
    groups, targets = torch.as_tensor(task.groups), torch.as_tensor(task.targets)
    for i in range(4):
        hooked[0, groups[i]] += targets[i] - hooked[0, groups[i]].mean(0)
    assert task.loss_terms(hooked, zero, c, task.hook_step)["hook"].abs().max() < 1e-12


def test_reward_weights_sum_to_the_stage_losses(scene, sim):
    """Dense: each stage's loss spread over its half; sparse: the paper's Eq. 33 at N/2 and N."""
    x = batch(sim.rest_positions)
    for mode in ("dense", "sparse"):
        t = SockTask(scene, sim.rest_positions, sim.handles, {"reward": mode})
        d = t.keypoint_distances(x)[0]
        total = {"hook": 0.0, "wear": 0.0}
        for step in range(1, t.horizon + 1):
            for k, val in t.loss_terms(x, x, x[:, :4], step).items():
                total[k] += float(val)
        assert total["hook"] == pytest.approx(float(d[:4].sum()), rel=1e-12)
        assert total["wear"] == pytest.approx(float(d[4:].sum()), rel=1e-12)


def test_gradcheck_of_loss_observe_and_drive(task, sim):
    gen = torch.Generator().manual_seed(0)
    n = sim.num_nodes
    x = (batch(sim.rest_positions) + 0.3 * torch.randn(1, n, 3, generator=gen, dtype=F64)).requires_grad_()
    v = torch.randn(1, n, 3, generator=gen, dtype=F64, requires_grad=True)
    c = (x.detach()[:, task.handles] + 0.1).requires_grad_()
    a = (0.5 * torch.randn(1, 12, generator=gen, dtype=F64)).requires_grad_()
    for step in (task.hook_step, task.horizon):
        assert torch.autograd.gradcheck(
            lambda x: torch.stack(list(task.loss_terms(x, v, c, step).values())), (x,), fast_mode=True)
    assert torch.autograd.gradcheck(lambda x, v, c: task.observe(x, v, c), (x, v, c), fast_mode=True)
    assert torch.autograd.gradcheck(lambda c, a: task.drive(c, a)[1].targets, (c, a))


def test_test_starts_are_distinct_in_range_and_outside_the_obstacles(task, sim):
    assert len(TEST_STARTS) == 20 and len(set(TEST_STARTS)) == 20
    lo, hi, yaw = task.start_low, task.start_high, task.start_yaw
    for s in TEST_STARTS:
        assert np.all(lo <= s[:3]) and np.all(np.array(s[:3]) <= hi) and abs(s[3]) <= yaw
    # Spread: every axis's range is covered from its lower to its upper quarter.
    arr = np.array(TEST_STARTS)
    span = np.concatenate([hi - lo, [2 * yaw]])
    assert np.all(arr.max(0) - arr.min(0) > 0.75 * span)
    rng = np.random.default_rng(0)
    corners = [(dx, dy, 0.0, yaw) for dx in (-1.0, 0.0, 1.0) for dy in (-1.0, 1.0) for yaw in (-45.0, 45.0)]
    starts = [task.start(s) for s in TEST_STARTS + tuple(corners)] + [task.sample_start(rng) for _ in range(10)]
    for s in starts:
        sim.reset(x=s.x)
        assert sim.obstacle_distance(0).min() > 0.75
        assert np.allclose(s.control, s.x[task.handles]) and not s.v.any()
        # A start is a rigid motion of the rest shape.
        assert np.allclose(np.linalg.norm(s.x[1:] - s.x[:-1], axis=1),
                           np.linalg.norm(task.rest[1:] - task.rest[:-1], axis=1))


def test_sampled_starts_are_seeded(task):
    a = task.sample_start(np.random.default_rng(7)).x
    b = task.sample_start(np.random.default_rng(7)).x
    c = task.sample_start(np.random.default_rng(8)).x
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_zero_action_rollout_stays_finite(task, sim):
    s = task.start(TEST_STARTS[5])
    sim.reset(x=s.x, v=s.v)
    c = batch(s.control)
    a = torch.zeros(1, task.action_dim, dtype=F64)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        for step in range(1, 21):
            c, drive = task.drive(c, a)
            sim.step(attachment_targets=drive.targets[0].numpy(), external_forces=None)
            x, v = batch(sim.positions), batch(sim.velocities)
            assert torch.isfinite(task.observe(x, v, c)).all()
            assert all(torch.isfinite(t).all() for t in task.loss_terms(x, v, c, step).values())
    assert np.allclose(c[0].numpy(), s.control)


@pytest.mark.parametrize("spec", [None, "abc", (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0, 0.0),
                                  (0.0, float("nan"), 0.0, 0.0), (0.0, 0.0, -0.5, 0.0),
                                  (2.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 90.0), {"dx": 0.0}])
def test_bad_start_specs_raise_input_error(task, spec):
    with pytest.raises(InputError, match="start"):
        task.start(spec)


def test_bad_arguments_raise_config_error(scene, sim):
    for cfg in ({"nope": 1}, {"action_scale": -1.0}, {"reward": "final"}, {"keypoint_nodes": 0},
                {"start_offset_low": [0.0, 0.0]}, {"start_offset_low": [2.0, 0.0, 0.0]}):
        with pytest.raises(ConfigError):
            SockTask(scene, sim.rest_positions, sim.handles, cfg)
