"""Hat-v0's task (diffcloth_gym/envs/hat_v0.py): shapes, the target state, gradients, starts,
the shipped target shape, bad input.

The shipped target is checked cheaply here: its first ``probe_steps`` steps are simulated again
and must match the stored probe (any change of the hat scene or the physics changes them, so
this fails until ``scripts/make_hat_target.py`` is run). The full regeneration (400 contact
steps, about 15-40 s) runs only with ``DIFFCLOTH_SLOW=1``."""

import math
import os

import numpy as np
import pytest
import torch

from diffcloth_gym import Simulator
from diffcloth_gym.envs.hat_v0 import (TARGET_FILE, TEST_STARTS, HatTask, head_sphere,
                                       make_target)
from diffcloth_gym.envs.task import Drive
from diffcloth_gym.errors import ConfigError, InputError
from diffcloth_gym.scenes import CONFIG_DIR, load_scene

N = 618


@pytest.fixture(scope="module")
def scene():
    return load_scene("hat")


@pytest.fixture(scope="module")
def sim():
    return Simulator.from_config("hat")


@pytest.fixture(scope="module")
def task(scene, sim):
    return HatTask(scene, sim.rest_positions, sim.handles, {})


@pytest.fixture(scope="module")
def stored():
    with np.load(CONFIG_DIR / TARGET_FILE) as z:
        return {k: np.array(z[k]) for k in z.files}


def batch(a, b=1):
    return torch.from_numpy(np.asarray(a, dtype=np.float64)).expand(b, *np.shape(a)).clone()


def test_dimensions(task):
    assert (task.obs_dim, task.action_dim, task.action_bound, task.horizon) == (3 * N + 15, 6, 1.0, 400)
    assert task.term_names == ("shape", "stretch", "direction")
    assert set(HatTask.default_config()) == {
        "start_radius", "action_scale", "shape_weight", "stretch_weight", "stretch_tolerance",
        "direction_weight", "direction_cos", "success_threshold", "target"}


def test_shapes_and_dtypes(task):
    g = torch.Generator().manual_seed(0)
    b = 3
    x = batch(task.target_np, b) + torch.randn(b, N, 3, generator=g, dtype=torch.float64)
    v = torch.randn(b, N, 3, generator=g, dtype=torch.float64)
    control = x[:, task.handles]
    action = torch.rand(b, 6, generator=g, dtype=torch.float64) * 2 - 1
    new, drive = task.drive(control, action)
    assert isinstance(drive, Drive) and drive.forces is None and drive.targets is new
    assert new.shape == (b, 2, 3) and new.dtype == torch.float64
    assert torch.allclose(new - control, 0.1 * action.reshape(b, 2, 3))
    obs = task.observe(x, v, new)
    assert obs.shape == (b, task.obs_dim) and obs.dtype == torch.float64
    terms = task.loss_terms(x, v, new, 1)
    assert tuple(terms) == task.term_names
    for t in terms.values():
        assert t.shape == (b,) and t.dtype == torch.float64 and torch.isfinite(t).all()
    ok = task.success(x, v, new)
    assert ok.shape == (b,) and ok.dtype == torch.bool


def test_observation_slices(task):
    g = torch.Generator().manual_seed(1)
    x = batch(task.target_np, 2) + 3 * torch.randn(2, N, 3, generator=g, dtype=torch.float64)
    v = torch.randn(2, N, 3, generator=g, dtype=torch.float64)
    obs = task.observe(x, v, None)
    target = torch.from_numpy(task.target_np)
    c, r = torch.from_numpy(task.head_center), task.head_radius
    n3 = 3 * N
    assert torch.equal(obs[:, :n3], (x - target).reshape(2, -1))
    point, elev = obs[:, n3:n3 + 3], obs[:, n3 + 3:n3 + 6]
    assert torch.allclose(point, c + elev)
    assert torch.allclose(elev.norm(dim=1), torch.full((2,), r, dtype=torch.float64))
    up = x.mean(1) - c
    assert torch.allclose(elev, r * up / up.norm(dim=1, keepdim=True))
    assert torch.allclose(obs[:, n3 + 6:n3 + 9], v.mean(1))
    top, (h0, front) = task.top, task.direction_nodes
    assert h0 == task.handles[0] and np.allclose(task.rest[front], [0.0, 1.7, 3.0]) and top == 0
    assert torch.equal(obs[:, n3 + 9:n3 + 12], x[:, top] - x[:, h0])
    assert torch.equal(obs[:, n3 + 12:], x[:, top] - x[:, front])


def test_target_state_has_zero_shape_observation_and_loss(task):
    x = batch(task.target_np, 2)
    obs = task.observe(x, torch.zeros_like(x), x[:, task.handles])
    assert torch.count_nonzero(obs[:, :3 * N]) == 0
    for name, t in task.loss_terms(x, torch.zeros_like(x), None, 400).items():
        assert torch.all(t == 0), name
    assert task.success(x, x, None).all()
    # Moved away, every term grows: a rigid shift costs shape only; upside down costs direction.
    shifted = x + torch.tensor([0.0, 5.0, 0.0], dtype=torch.float64)
    terms = task.loss_terms(shifted, x, None, 1)
    assert torch.allclose(terms["shape"], torch.full((2,), 4.5 / 3, dtype=torch.float64))
    assert torch.all(terms["stretch"] == 0) and torch.all(terms["direction"] == 0)
    assert not task.success(shifted, x, None).any()
    # Turned over about the handles' axis (x) or about the front-back axis (z).
    for flip in ([1.0, -1.0, -1.0], [-1.0, -1.0, 1.0]):
        flipped = x * torch.tensor(flip, dtype=torch.float64)
        assert (task.loss_terms(flipped, x, None, 1)["direction"] > 4.5).all(), flip
    spread = x.clone()
    spread[:, task.handles[0], 0] += 1.5
    assert torch.allclose(task.loss_terms(spread, x, None, 1)["stretch"], torch.full((2,), 0.2 * 0.5, dtype=torch.float64), atol=1e-4)


def small_task(**config):
    """A 7-node stand-in for gradcheck: node 0 is the top, nodes 5 and 6 the handles (+x, -x),
    node 4 the front (+z)."""
    rng = np.random.default_rng(3)
    rest = rng.normal(size=(7, 3))
    rest[0] = [0.0, 5.0, 0.0]
    rest[4, 2], rest[5, 0], rest[6, 0] = 4.0, 3.0, -3.0
    target = rest + rng.normal(scale=0.8, size=rest.shape)
    scene = {"steps": 10, "obstacles": [{"shape": {"kind": "union", "parts": [
        {"kind": "capsule", "a": [0, -3, 0], "b": [0, -1, 0], "radius": 0.5},
        {"kind": "sphere", "center": [0.1, 0.2, -0.3], "radius": 1.5}]}}]}
    return HatTask(scene, rest, [5, 6], {"target": target, "stretch_tolerance": 0.05, **config})


def test_gradients_match_finite_differences():
    task = small_task(direction_cos=0.99)
    assert task.direction_nodes == [5, 4]
    g = torch.Generator().manual_seed(4)
    x = (batch(task.target_np, 2) + torch.randn(2, 7, 3, generator=g, dtype=torch.float64)).requires_grad_()
    v = torch.randn(2, 7, 3, generator=g, dtype=torch.float64, requires_grad=True)
    control = torch.randn(2, 2, 3, generator=g, dtype=torch.float64, requires_grad=True)
    action = torch.randn(2, 6, generator=g, dtype=torch.float64, requires_grad=True)
    terms = task.loss_terms(x, v, control, 1)
    # The sample exercises the active branches of the clamped terms too.
    assert (terms["stretch"] > 0).any() and (terms["direction"] > 0).any()
    for name in task.term_names:
        assert torch.autograd.gradcheck(lambda x, name=name: task.loss_terms(x, v, control, 1)[name], (x,)), name
    assert torch.autograd.gradcheck(lambda x, v: task.observe(x, v, control), (x, v))
    assert torch.autograd.gradcheck(lambda c, a: task.drive(c, a)[0], (control, action))
    # The graph runs from the loss through drive back into the action (step_grad's chain).
    new, drive = task.drive(control, action)
    (drive.targets.sum() + task.loss_terms(x + new.mean(), v, new, 1)["shape"].sum()).backward()
    assert action.grad is not None and torch.isfinite(action.grad).all()


def test_test_starts_are_20_distinct_starts_spread_over_the_hemisphere():
    assert len(TEST_STARTS) == 20 and len(set(TEST_STARTS)) == 20
    for polar, azimuth in TEST_STARTS:
        assert 0 <= polar < 90 and 0 <= azimuth < 360
    # Equal area: cos(polar) sits at the midpoints of 20 equal bands.
    cos = np.sort(np.cos(np.radians([p for p, _ in TEST_STARTS])))
    assert np.allclose(cos, (np.arange(20) + 0.5) / 20, atol=2e-4)


def test_starts_are_outside_the_head_at_the_documented_distance(task, sim, scene):
    thickness = scene.get("contact", {}).get("thickness", 0.01)
    center, radius = head_sphere(scene)
    assert np.allclose(center, 0) and radius == 2.1
    for spec in list(TEST_STARTS) + [(0.0, 0.0), (89.99, 0.0), (89.99, 270.0)]:
        s = task.start(spec)
        assert s.x.shape == (N, 3) and s.v.shape == (N, 3) and s.control.shape == (2, 3)
        assert np.all(s.v == 0) and np.array_equal(s.control, s.x[task.handles])
        centroid = s.x.mean(axis=0)
        assert np.isclose(np.linalg.norm(centroid - center), 10.645)
        polar, azimuth = spec
        assert np.isclose(math.degrees(math.atan2(np.hypot(*(centroid - center)[[0, 2]]), (centroid - center)[1])), polar)
        # Rigid: the rest shape translated, not rotated.
        assert np.allclose(s.x - s.x.mean(0), sim.rest_positions - sim.rest_positions.mean(0))
        sim.reset(x=s.x)
        assert sim.obstacle_distance(0).min() > 5.0 > thickness


def test_sample_start_is_seeded_and_in_range(task):
    a = task.sample_start(np.random.default_rng(7))
    b = task.sample_start(np.random.default_rng(7))
    assert np.array_equal(a.x, b.x) and np.array_equal(a.control, b.control)
    rng = np.random.default_rng(8)
    for _ in range(20):
        d = task.sample_start(rng).x.mean(0) - task.head_center
        assert np.isclose(np.linalg.norm(d), 10.645) and d[1] > 0


def test_short_rollout_from_a_start_stays_finite(task):
    sim = Simulator.from_config("hat")
    s = task.start(TEST_STARTS[7])
    sim.reset(x=s.x)
    assert np.allclose(sim.attachment_targets, s.control)
    control = batch(s.control)
    with torch.no_grad():
        for step in range(1, 21):
            action = torch.zeros(1, 6, dtype=torch.float64)
            action[0, 1] = action[0, 4] = -0.5 if step > 10 else 0.0
            control, drive = task.drive(control, action)
            sim.step(attachment_targets=drive.targets[0].numpy())
            x, v = batch(sim.positions), batch(sim.velocities)
            obs = task.observe(x, v, control)
            terms = task.loss_terms(x, v, control, step)
            assert torch.isfinite(obs).all() and all(torch.isfinite(t).all() for t in terms.values())
    assert np.isfinite(sim.positions).all() and sim.obstacle_distance(0).min() > 1.0


@pytest.mark.parametrize("spec", [
    (45.0,), (45.0, 10.0, 0.0), "ab", None, 5.0, {"polar": 1, "azimuth": 2}, ("a", "b"),
    (float("nan"), 0.0), (0.0, float("inf")), (90.0, 0.0), (-1.0, 0.0), (0.0, 360.0), (10.0, -0.5),
])
def test_bad_start_raises_input_error_naming_start(task, spec):
    with pytest.raises(InputError, match="start"):
        task.start(spec)


@pytest.mark.parametrize("config, needle", [
    ({"bogus": 1}, "unknown"),
    ({"action_scale": 0.0}, "action_scale"),
    ({"shape_weight": -1.0}, "shape_weight"),
    ({"start_radius": float("nan")}, "start_radius"),
    ({"direction_cos": 2.0}, "direction_cos"),
    ({"target": np.zeros((5, 3))}, "target"),
])
def test_bad_config_raises_config_error(scene, sim, config, needle):
    with pytest.raises(ConfigError, match=needle):
        HatTask(scene, sim.rest_positions, sim.handles, config)


def test_shipped_target_rests_on_the_head(task, stored, scene):
    target = stored["target"]
    assert target.shape == (N, 3) and target.dtype == np.float64 and np.isfinite(target).all()
    assert np.array_equal(task.target_np, target)
    center, radius = head_sphere(scene)
    gap = np.linalg.norm(target - center, axis=1) - radius
    thickness = scene.get("contact", {}).get("thickness", 0.01)
    assert gap.min() > thickness - 1e-6
    assert gap[task.top] < thickness + 0.01, "the crown rests on the head"
    # Upright, handles held 0.1 below their rest height, not stretched between them.
    h0, h1 = task.handles
    assert np.allclose(target[[h0, h1], 1], -0.4, atol=1e-3)
    assert abs(np.linalg.norm(target[h0] - target[h1]) - 6.0) < 1e-2


def test_shipped_target_probe_matches_the_physics(stored):
    """The first steps of make_target, simulated again, match the stored ones: fails after a
    change of the hat scene or the physics until scripts/make_hat_target.py is run."""
    steps = int(stored["probe_steps"])
    _, probe = make_target(steps=steps, probe_steps=steps)
    assert np.allclose(probe, stored["probe"], rtol=0, atol=1e-9), (
        "hat_target.npz is stale: run .venv/bin/python scripts/make_hat_target.py")


@pytest.mark.skipif(not os.environ.get("DIFFCLOTH_SLOW"), reason="400 contact steps; set DIFFCLOTH_SLOW=1")
def test_shipped_target_matches_make_target(stored):
    target, probe = make_target(probe_steps=int(stored["probe_steps"]))
    assert np.allclose(target, stored["target"], rtol=0, atol=1e-9)
    assert np.allclose(probe, stored["probe"], rtol=0, atol=1e-9)
