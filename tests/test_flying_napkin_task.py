"""FlyingNapkin-v0's task (diffcloth_gym/envs/flying_napkin_v0.py): resolution, shapes, the
loss at the target, gradients, starts, a short rollout without contact, bad start specs."""

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from diffcloth_gym import Simulator, load_scene  # noqa: E402
from diffcloth_gym.envs.flying_napkin_v0 import TEST_STARTS, FlyingNapkinTask  # noqa: E402
from diffcloth_gym.errors import ConfigError, InputError  # noqa: E402

F64 = torch.float64


def build(**config):
    """The scene, simulator and task as the env builds them: scene overrides, then the task."""
    cfg = FlyingNapkinTask.default_config()
    cfg.update(config)
    scene = load_scene("napkin")
    for table, entries in FlyingNapkinTask.scene_overrides(cfg).items():
        scene.setdefault(table, {}).update(entries)
    sim = Simulator.from_config(scene)
    return scene, sim, FlyingNapkinTask(scene, sim.rest_positions, sim.handles, cfg)


@pytest.fixture(scope="module")
def small():
    return build(resolution=4)


def batch(a):
    return torch.as_tensor(np.asarray(a), dtype=F64)[None]


@pytest.mark.parametrize("r, dim", [(4, 48), (5, 75), (7, 147), (10, 300)])
def test_resolution_sets_the_action_dimension(r, dim):
    assert FlyingNapkinTask.scene_overrides({"resolution": r}) == {"mesh": {"rows": r, "cols": r}}
    _, sim, task = build(resolution=r)
    assert sim.num_nodes == r * r
    assert (task.action_dim, task.obs_dim, task.action_bound) == (dim, 2 * dim, 1.0)
    # max_force = max_accel x mean node mass (0.8 kg over r^2 nodes).
    assert task.max_force == pytest.approx(20.0 * sim.masses.sum() / (r * r))


def test_default_is_ten_by_ten():
    assert FlyingNapkinTask.scene_overrides(None) == {"mesh": {"rows": 10, "cols": 10}}
    assert FlyingNapkinTask.default_config()["resolution"] == 10


def test_dimensions_and_dtypes(small):
    _, sim, task = small
    n = sim.num_nodes
    assert task.horizon == 100
    s = task.start(TEST_STARTS[0])
    assert s.x.shape == s.v.shape == (n, 3) and s.control.shape == (0, 3)
    x, v, c = batch(s.x).repeat(3, 1, 1), batch(s.v).repeat(3, 1, 1), batch(s.control).repeat(3, 1, 1)
    obs = task.observe(x, v, c)
    assert obs.shape == (3, task.obs_dim) and obs.dtype == F64
    a = torch.linspace(-1, 1, 3 * task.action_dim, dtype=F64).reshape(3, -1)
    c2, drive = task.drive(c, a)
    assert c2.shape == (3, 0, 3) and drive.targets is None
    assert drive.forces.shape == (3, n, 3)
    assert torch.allclose(drive.forces, task.max_force * a.reshape(3, n, 3))
    terms = task.loss_terms(x, v, c, 1)
    assert set(terms) == set(task.term_names) == {"distance"}
    assert terms["distance"].shape == (3,) and terms["distance"].dtype == F64
    ok = task.success(x, v, c)
    assert ok.shape == (3,) and ok.dtype == torch.bool and not ok.any()


def test_target_is_a_turned_and_moved_rest_shape(small):
    _, sim, task = small
    rest, target = sim.rest_positions, task.target
    assert np.allclose(target.mean(0) - rest.mean(0), [0.0, 1.0, 1.5])
    pair = lambda p: np.linalg.norm(p[:, None] - p[None], axis=-1)  # noqa: E731
    assert np.allclose(pair(target), pair(rest))


def test_loss_is_zero_at_the_target(small):
    _, _, task = small
    x = batch(task.target)
    zero = torch.zeros_like(x)
    c = torch.zeros(1, 0, 3, dtype=F64)
    for step in (1, task.horizon):
        assert task.loss_terms(x, zero, c, step)["distance"].abs().max() < 1e-14
    assert task.observe(x, zero, c).abs().max() < 1e-14
    assert task.success(x, zero, c).all()


def test_distance_is_the_mean_squared_node_distance_bitwise():
    # The loss spells out x + y + z (speed); it must stay bitwise torch's sum over the axis,
    # so rewards do not change with the spelling. Random batches of the default 10 x 10 napkin.
    _, _, task = build()
    x = torch.as_tensor(task.target, dtype=F64) + torch.randn(32, 100, 3, dtype=F64,
                                                              generator=torch.Generator().manual_seed(0))
    want = ((x - torch.as_tensor(task.target, dtype=F64)) ** 2).sum(dim=-1).mean(dim=-1)
    assert torch.equal(task.mean_squared_distance(x), want)


def test_reward_weights(small):
    _, sim, task = small
    x = batch(sim.rest_positions)
    c = torch.zeros(1, 0, 3, dtype=F64)
    d = float(task.mean_squared_distance(x))
    dense = sum(float(task.loss_terms(x, x, c, s)["distance"]) for s in range(1, task.horizon + 1))
    assert dense == pytest.approx(d)
    _, _, final = build(resolution=4, reward="final")
    assert [float(final.loss_terms(x, x, c, s)["distance"]) for s in (1, 99)] == [0.0, 0.0]
    assert float(final.loss_terms(x, x, c, final.horizon)["distance"]) == pytest.approx(d)


def test_gradcheck_of_loss_observe_and_drive(small):
    _, sim, task = small
    gen = torch.Generator().manual_seed(1)
    n = sim.num_nodes
    x = (batch(sim.rest_positions) + 0.2 * torch.randn(2, n, 3, generator=gen, dtype=F64)).requires_grad_()
    v = torch.randn(2, n, 3, generator=gen, dtype=F64, requires_grad=True)
    c = torch.zeros(2, 0, 3, dtype=F64)
    a = torch.rand(2, task.action_dim, generator=gen, dtype=F64).mul(2).sub(1).requires_grad_()
    assert torch.autograd.gradcheck(lambda x: task.loss_terms(x, v, c, 3)["distance"], (x,))
    assert torch.autograd.gradcheck(lambda x, v: task.observe(x, v, c), (x, v))
    assert torch.autograd.gradcheck(lambda a: task.drive(c, a)[1].forces, (a,))


def test_test_starts_are_distinct_and_in_range(small):
    _, _, task = small
    assert len(TEST_STARTS) == 20 and len(set(TEST_STARTS)) == 20
    arr = np.array(TEST_STARTS)
    assert np.all(np.abs(arr) <= task.start_offset)
    assert np.all(arr.max(0) - arr.min(0) > 1.5 * task.start_offset)
    for spec in TEST_STARTS:
        s = task.start(spec)
        assert np.allclose(s.x - task.rest, spec) and not s.v.any()
    rng = np.random.default_rng(0)
    for _ in range(10):
        d = task.sample_start(rng).x - task.rest
        assert np.allclose(d, d[0]) and np.all(np.abs(d[0]) <= task.start_offset)


def test_rollout_is_finite_and_contact_free(small):
    _, sim, task = small
    s = task.start(TEST_STARTS[3])
    sim.reset(x=s.x, v=s.v)
    sim.reset_profile()
    c = batch(s.control)
    up = torch.zeros(1, task.action_dim, dtype=F64)
    for step in range(1, 21):
        c, drive = task.drive(c, up)
        sim.step(attachment_targets=None, external_forces=drive.forces[0].numpy())
        x, v = batch(sim.positions), batch(sim.velocities)
        assert torch.isfinite(task.observe(x, v, c)).all()
        assert torch.isfinite(task.loss_terms(x, v, c, step)["distance"]).all()
    # Falling under gravity with zero force.
    assert sim.positions[:, 1].mean() < s.x[:, 1].mean()
    prof = sim.profile()
    assert prof["steps"] == 20 and prof["contact_s"] == 0.0 and prof["detection_s"] == 0.0


def test_forces_reach_the_simulator(small):
    """A full upward action lifts the napkin against gravity (max_accel 20 > g)."""
    _, sim, task = small
    s = task.start((0.0, 0.0, 0.0))
    sim.reset(x=s.x, v=s.v)
    a = torch.zeros(1, task.action_dim, dtype=F64)
    a.view(1, -1, 3)[..., 1] = 1.0
    _, drive = task.drive(torch.zeros(1, 0, 3, dtype=F64), a)
    for _ in range(10):
        sim.step(external_forces=drive.forces[0].numpy())
    assert sim.positions[:, 1].mean() > s.x[:, 1].mean()


@pytest.mark.parametrize("spec", [None, "abc", (0.0, 0.0), (0.0, 0.0, 0.0, 0.0), (0.0, float("inf"), 0.0),
                                  (0.3, 0.0, 0.0), {"dx": 0.0}])
def test_bad_start_specs_raise_input_error(small, spec):
    _, _, task = small
    with pytest.raises(InputError, match="start"):
        task.start(spec)


def test_bad_arguments_raise_config_error(small):
    scene, sim, _ = small
    for cfg in ({"resolution": 1}, {"resolution": 4.5}, {"nope": 0}):
        with pytest.raises(ConfigError):
            FlyingNapkinTask.scene_overrides(cfg)
    for cfg in ({"resolution": 5}, {"resolution": 4, "max_accel": 0.0}, {"resolution": 4, "reward": "sparse"},
                {"resolution": 4, "target_offset": [1.0]}):
        with pytest.raises(ConfigError):
            FlyingNapkinTask(scene, sim.rest_positions, sim.handles, cfg)
