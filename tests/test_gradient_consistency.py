"""Gradients at the settings users run agree with the gradients of a converged trajectory.

The adjoint linearizes each step at its end state; the reference implementation at its default
tolerance is 1e10 times off on the Hat (DESIGN.md section 3). Ours must be right without any
clipping at the ``gradient`` solver preset (tolerance 1e-11). Recording never changes the
trajectory: a recorded rollout is the unrecorded one, bit for bit, and at the default
``simulation`` preset (1e-8) backward says its steps are too loose, with the figure.
"""

import warnings

import numpy as np
import pytest

from diffcloth_gym import ConvergenceWarning, Simulator
from diffcloth_gym.scenes import contact_free, load_scene

STEPS = 400


def rollout_gradients(cfg, **solver):
    sim = Simulator.from_config(cfg)
    sim.set_solver(**solver)
    rng = np.random.default_rng(0)
    sim.set_recording(True)
    sim.reset(v=rng.normal(0, 0.2, (sim.num_nodes, 3)))
    t0 = sim.attachment_targets
    target = sim.rest_positions + np.array([0.0, -1.0, 0.0])
    xs = []
    for k in range(STEPS):
        sim.step(attachment_targets=t0 + np.array([0.0, -0.003 * k, 0.002 * k]))
        xs.append(sim.positions)
    d = np.array(xs) - target
    # Smooth-L1 to a target shape on every step (controller-style loss).
    dl_dx = np.where(np.abs(d) < 1, d, np.sign(d)) / sim.num_nodes
    g = sim.backward(dl_dx=dl_dx, solver="krylov", tolerance=1e-12)
    return g, np.concatenate([a.ravel() for a in g["attachment_targets"]])


def compare(a, b):
    a, b = np.ravel(a), np.ravel(b)
    return np.linalg.norm(a - b) / np.linalg.norm(b), a @ b / (np.linalg.norm(a) * np.linalg.norm(b))


@pytest.mark.parametrize("name, mesh", [("hat", {}), ("sock", {}), ("wind", {"rows": 24, "cols": 24})])
def test_gradient_preset_gives_the_converged_gradient(name, mesh):
    cfg = contact_free(load_scene(name, **mesh))
    default, default_targets = rollout_gradients(cfg, preset="gradient")
    converged, converged_targets = rollout_gradients(cfg, tolerance=1e-12, max_iterations=5000)
    assert default["warnings"] == []
    for got, ref in [(default["v0"], converged["v0"]), (default_targets, converged_targets)]:
        rel, cos = compare(got, ref)
        assert cos >= 0.99 and rel <= 1e-2, (name, rel, cos)


@pytest.mark.parametrize("name, bend_model", [("sock", None), ("sock", "vertex"), ("hat", None)])
def test_full_scenes_with_contact_give_the_converged_gradient(name, bend_model):
    """The full scenes, 400 steps: the Sock with its foot, leg and self-contact (friction in
    every contact branch), the Hat on its head. The Hat buckles against the head at about
    step 70, where forward differences of 1e-7 grow 1e4-fold: recorded at 1e-10 its trajectory
    parted from the 1e-12 one (gradients 0.56 apart); at the default 1e-11 they agree to 3e-3.
    Its friction gradient is checked. With the edge bending model (the default) self-contact
    never pushes on either scene (mu_self is 0); the Sock with the per-vertex model folds
    onto itself, so that case keeps the self-contact friction gradient checked. A few Hat steps
    sit near a saddle for thousands of iterations: at the preset's former cap of 2000 two
    stopped at 7e-9 (the backward warned), and the 1e-12 reference needs more than 5000."""
    cfg = load_scene(name)
    if bend_model is not None:
        cfg["material"]["bend_model"] = bend_model
    with warnings.catch_warnings():
        # Steps that stop at a cap warn; backward reports any above the trusted 1e-9 (asserted).
        warnings.simplefilter("ignore", ConvergenceWarning)
        default, default_targets = rollout_gradients(cfg, preset="gradient")
        converged, converged_targets = rollout_gradients(cfg, tolerance=1e-12, max_iterations=20000)
    assert default["warnings"] == [] and converged["warnings"] == []
    pairs = [(default["v0"], converged["v0"]), (default_targets, converged_targets),
             (default["mu_obstacles"], converged["mu_obstacles"])]
    if bend_model is None:
        assert default["mu_self"] == 0.0 and converged["mu_self"] == 0.0
    else:
        pairs.append((default["mu_self"], converged["mu_self"]))
    for got, ref in pairs:
        rel, cos = compare(got, ref)
        assert cos >= 0.99 and rel <= 1e-2, (name, rel, cos)


def test_loose_recording_is_reported_not_hidden():
    cfg = contact_free(load_scene("hat"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        loose, _ = rollout_gradients(cfg, tolerance=1e-6)
    assert any("recorded steps stopped above" in w for w in loose["warnings"])


def test_recording_does_not_change_the_trajectory():
    """The Hat on its head (contact, friction, self-collision), 60 steps at the default
    preset: recorded and unrecorded rollouts agree bit for bit, and backward says the default's
    steps (1e-8) are looser than the adjoint needs, with the figure and the remedy."""
    runs = []
    for record in (False, True):
        sim = Simulator.from_config("hat")
        sim.set_recording(record)
        t0 = sim.attachment_targets
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            for k in range(60):
                sim.step(attachment_targets=t0 + np.array([0.0, -0.003 * k, 0.002 * k]))
        runs.append(sim.positions)
    assert np.array_equal(runs[0], runs[1])
    g = sim.backward(dl_dx=np.ones((sim.num_nodes, 3)))
    (w,) = [w for w in g["warnings"] if "recorded steps stopped above" in w]
    assert "residual 1e-9" in w and 'preset "gradient"' in w
