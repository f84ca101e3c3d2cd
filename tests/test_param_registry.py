"""Issue 14 items 0-1: one name per parameter (friction included) for params(), set_params,
the gradient dict and diffcloth_gym.torch; per-step gradients as arrays; a terminal loss
without padding; recording that never changes the solver's accuracy."""

import numpy as np
import pytest

from diffcloth_gym import ConfigError, ParameterError, Simulator
from diffcloth_gym.errors import InputError
from diffcloth_gym.scenes import load_scene


def slope(rows=4):
    return Simulator.from_config(load_scene("slope", rows=rows, cols=rows))


def test_every_registry_name_round_trips_and_names_its_gradient():
    sim = Simulator.from_config(load_scene("sphere", rows=6, cols=6))
    names = set(Simulator.PARAM_NAMES)
    assert {"mu_obstacles", "mu_self", "k_stretch", "gravity"} <= names and "h" not in names
    p = sim.params()
    assert set(p) == names | {"h"}
    assert p["mu_obstacles"] == [0.3] and p["mu_self"] == 0.1
    sim.set_params(mu_obstacles=[0.45], mu_self=0.2, k_stretch=160.0)
    p = sim.params()
    assert p["mu_obstacles"] == [0.45] and p["mu_self"] == 0.2 and p["k_stretch"] == 160.0
    sim.set_recording(True)
    sim.step(steps=3)
    g = sim.backward(dl_dx={-1: np.ones((sim.num_nodes, 3))})
    assert names <= set(g)
    assert len(g["mu_obstacles"]) == 1 and isinstance(g["mu_self"], float)


def test_bad_friction_values_are_refused_by_name_and_change_nothing():
    sim = slope()
    with pytest.raises(ParameterError, match="mu_obstacles must have one number per obstacle"):
        sim.set_params(mu_obstacles=[0.1, 0.2])
    with pytest.raises(ParameterError, match=r"mu_obstacles\[0\]"):
        sim.set_params(k_stretch=10.0, mu_obstacles=[-1.0])
    with pytest.raises(ParameterError, match="mu_self: the scene has no self-collision"):
        sim.set_params(mu_self=0.1)
    with pytest.raises(ParameterError, match="one number per obstacle"):
        sim.set_params(mu_obstacles=0.3)
    assert sim.params()["k_stretch"] == 50.0 and sim.params()["mu_obstacles"] == [0.5]
    assert "mu_self" not in sim.params()


def test_per_step_gradients_are_arrays_and_a_terminal_loss_needs_no_padding():
    sim = Simulator.from_config(load_scene("wind", rows=5, cols=5))
    sim.set_solver(preset="gradient")
    sim.set_recording(True)
    sim.step(steps=6)
    n = sim.num_nodes
    final = np.random.default_rng(0).normal(size=(n, 3))
    padded = np.zeros((6, n, 3))
    padded[-1] = final
    full = sim.backward(dl_dx=padded)
    for dl in ({-1: final}, {5: final}, final):
        g = sim.backward(dl_dx=dl)
        assert np.array_equal(g["v0"], full["v0"])
    assert isinstance(full["attachment_targets"], np.ndarray) and full["attachment_targets"].shape == (6, 2, 3)
    assert full["external_forces"].shape == (6, 0, 3) and full["external_forces_constant"] is None
    assert full["iterations"].shape == (6,) and full["warnings"] == []
    with pytest.raises(InputError, match="step 6"):
        sim.backward(dl_dx={6: final})


def test_solver_presets_and_the_retired_record_settings():
    sim = slope()
    assert sim.solver()["tolerance"] == 1e-8 and sim.solver()["max_iterations"] == 300
    sim.set_solver(preset="gradient")
    assert sim.solver()["tolerance"] == 1e-11 and sim.solver()["max_iterations"] == 10000
    sim.set_solver(preset="gradient", tolerance=1e-10)  # explicit settings override the preset
    assert sim.solver()["tolerance"] == 1e-10
    # The envs' way of saying "recorded steps like the others" keeps working ...
    sim.set_solver(tolerance=1e-9, record_tolerance=1e-9, max_iterations=500, record_max_iterations=500)
    # ... and a different record tolerance is refused, not silently ignored.
    with pytest.raises(ParameterError, match="record_tolerance is retired"):
        sim.set_solver(record_tolerance=1e-12)
    with pytest.raises(ParameterError, match="preset must be"):
        sim.set_solver(preset="fast")
    cfg = load_scene("slope", rows=4, cols=4)
    cfg["solver"] = {"preset": "gradient", "max_iterations": 900}
    s = Simulator.from_config(cfg).solver()
    assert s["tolerance"] == 1e-11 and s["max_iterations"] == 900
    cfg["solver"] = {"tolerance": 1e-9, "record_tolerance": 1e-9}  # the envs' configs
    assert Simulator.from_config(cfg).solver()["tolerance"] == 1e-9
    cfg["solver"] = {"record_tolerance": 1e-11}
    with pytest.raises(ConfigError, match="record_tolerance is retired"):
        Simulator.from_config(cfg)


def test_torch_differentiates_obstacle_friction():
    torch = pytest.importorskip("torch")
    from diffcloth_gym import torch as dtorch

    sim = slope()
    sim.set_solver(preset="gradient")
    rng = np.random.default_rng(1)
    x0 = torch.tensor(sim.rest_positions)
    v0 = torch.tensor(rng.normal(0, 0.3, (sim.num_nodes, 3)))
    mu = torch.tensor([0.5], dtype=torch.float64, requires_grad=True)
    w = torch.tensor(rng.normal(size=(sim.num_nodes, 3)))

    def loss_of(m):
        xs, _ = dtorch.rollout(sim, x0, v0, params={"mu_obstacles": m}, steps=8)
        return (xs[-1] * w).sum()

    loss_of(mu).backward()
    eps = 1e-6
    with torch.no_grad():
        fd = (loss_of(torch.tensor([0.5 + eps], dtype=torch.float64))
              - loss_of(torch.tensor([0.5 - eps], dtype=torch.float64))) / (2 * eps)
    assert mu.grad.shape == (1,)
    assert abs(mu.grad[0].item() - fd.item()) <= 1e-5 * max(1.0, abs(fd.item())), (mu.grad, fd)
