"""diffcloth_gym.optim with small budgets: each parameterization's gradient against central
differences (forward converged to 1e-11: its loss noise, about 1e-10, over 2 eps = 2e-4 is
5e-7, and the truncation error eps^2 1e-8 is as small; errors are relative to the gradient's
largest entry), the
drivers under one step budget, the step counter, and gradcheck's contact report."""

import numpy as np
import pytest

pytest.importorskip("scipy")
pytest.importorskip("cma")

from diffcloth_gym import Simulator  # noqa: E402
from diffcloth_gym.optim import (  # noqa: E402
    BudgetExhausted, HermiteSpline, KeypointDistance, Objective, PhysicalParams, ShapeMatch, SmoothL1, Stack,
    TrajectoryMatch, flying_napkin, gradcheck, initial_guess, run_cmaes, run_lbfgsb, run_one_plus_one,
)
from diffcloth_gym.scenes import load_scene  # noqa: E402


def check(obj, theta, eps=1e-4, tol=1e-5, indices=None):
    report = gradcheck(obj, theta, indices=indices, eps=eps)
    assert report.max_error < tol, str(report)
    return report


def test_spline_gradient_with_composed_losses():
    sim = Simulator.from_config(load_scene("wind", rows=5, cols=5))
    spline = HermiteSpline(sim.attachment_targets, reach=0.5, tangent=1.0)
    steps = 12
    rest = sim.rest_positions
    loss = (ShapeMatch(rest + [0.2, 0.1, 0.3], translation=False) + 0.5 * SmoothL1(rest + [0, -0.5, 0], step=5, beta=0.1)
            + KeypointDistance([0, 3], rest[[0, 3]] + 0.3, step=-2))
    obj = Objective(sim, spline, loss, steps)
    theta = np.random.default_rng(0).uniform(-0.3, 0.3, spline.size)
    targets = spline.targets(theta, steps)
    assert np.allclose(targets[-1], sim.attachment_targets + theta.reshape(2, 3, 3)[:, 0])
    check(obj, theta)


def test_node_force_gradient():
    task = flying_napkin(resolution=4, steps=10)
    obj = task.objective()
    theta = task.truth + np.random.default_rng(1).normal(0, 0.5, task.param.size)
    check(obj, theta, indices=range(0, task.param.size, 5))


def test_physical_parameter_gradient_with_friction():
    """Stretch, density and the slope's friction on a ribbon sliding with random velocities,
    stacked with a constant force on every node."""
    sim = Simulator.from_config(load_scene("slope", rows=4, cols=4))
    steps = 10
    sim.set_solver(preset="gradient")
    sim.reset(v=np.random.default_rng(2).normal(0, 0.3, (sim.num_nodes, 3)))
    v0 = sim.velocities
    sim.step(steps=steps)
    phys = PhysicalParams(sim, {"k_stretch": (10.0, 100.0), "density": (0.1, 0.4), "mu_obstacles[0]": (0.0, 1.0)})
    target = sim.positions + 0.05
    obj = Objective(sim, phys, ShapeMatch(target, squared=True), steps, v0=v0)
    report = check(obj, [60.0, 0.25, 0.4], eps=[1e-3, 1e-5, 1e-5])
    assert all(e.switched == [] for e in report.entries), str(report)
    assert phys.inputs(np.array([60.0, 0.25, 0.4]), steps).params == {"k_stretch": 60.0, "density": 0.25,
                                                                        "mu_obstacles": [0.4]}


def test_step_counter_counts_what_ran():
    task = flying_napkin(resolution=4, steps=7)
    obj = task.objective(budget=30)
    sim = task.sim
    sim.reset_profile()
    obj(task.truth)
    assert (obj.forward_steps, obj.backward_steps, obj.steps_used) == (7, 7, 14)
    obj.loss(task.truth)
    assert (obj.forward_steps, obj.steps_used) == (14, 21)
    assert sim.profile()["steps"] == obj.forward_steps
    with pytest.raises(BudgetExhausted):
        obj(task.truth)  # 21 + 14 > 30: refused before running
    assert obj.steps_used == 21 and sim.profile()["steps"] == 14
    obj.loss(task.truth)
    assert obj.steps_used == 28 and [h["steps"] for h in obj.history] == [14, 21, 28]


@pytest.mark.parametrize("driver", [run_lbfgsb, run_cmaes, run_one_plus_one])
def test_drivers_share_start_and_budget(driver):
    task = flying_napkin(resolution=4, steps=8)
    obj = task.objective()
    u0 = initial_guess(task.param, seed=3)
    run = driver(obj, u0, budget=400, seed=3, show_progress=False)
    assert run.steps_used <= 400 and run.history[0]["steps"] in (8, 16)
    assert run.initial_loss == pytest.approx(obj.loss_fn(obj.rollout(obj.from_unit(u0)))[0])
    best = [h["best"] for h in run.history]
    assert best == sorted(best, reverse=True) and run.best_loss < run.initial_loss
    if driver is run_lbfgsb:
        assert run.best_loss < 0.2 * run.initial_loss


def test_lbfgsb_lowers_the_loss_on_a_short_hat_rollout():
    """The Hat on its head with contact: two effectors on splines, the final shape matched to
    the rest shape moved down by 0.3; 4 evaluations with gradients."""
    sim = Simulator.from_config("hat")
    steps = 15
    spline = HermiteSpline(sim.attachment_targets, reach=0.5, tangent=0.5)
    obj = Objective(sim, spline, ShapeMatch(sim.rest_positions + [0.0, -0.3, 0.0]), steps)
    run = run_lbfgsb(obj, np.full(spline.size, 0.5), budget=8 * steps, show_progress=False)
    assert run.evaluations == 4 and run.best_loss < 0.9 * run.initial_loss, [h["loss"] for h in run.history]


def test_gradcheck_reports_contact_switches_between_the_runs():
    """A ribbon landing on the slope: a large eps on the drop height changes which contacts
    exist at which step, and the report names them."""
    sim = Simulator.from_config(load_scene("slope", rows=4, cols=4))
    phys = PhysicalParams(sim, {"gravity[1]": (-20.0, 0.0)})
    steps = 6
    x0 = sim.rest_positions + np.array([0.0, 0.02, 0.0])
    obj = Objective(sim, phys, TrajectoryMatch(np.repeat(x0[None], steps, axis=0), squared=True), steps, x0=x0)
    report = gradcheck(obj, [-9.8], eps=3.0)
    (entry,) = report.entries
    assert entry.switched, str(report)
    step, a, b, o, before, after = entry.switched[0]
    assert o == 0 and b == -1 and before != after and {before, after} <= {-1, 0, 1, 2}
    assert "switched" in str(report)
