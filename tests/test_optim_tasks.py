"""The paper's Sec. 6 tasks as shipped (diffcloth_gym.optim.TASKS): each builds, its loss's
gradient matches central differences on a short rollout (gradient preset, error relative to
the gradient's largest entry), identification recovers a known parameter on a tiny version,
and the shipped procedural meshes are what their generators make."""

import math

import numpy as np
import pytest

from diffcloth_gym.errors import InputError
from diffcloth_gym.optim import (TASKS, Fixed, GroupKeypoints, HeightMatch, PhysicalParams, Stack, gradcheck,
                                 initial_guess, run_lbfgsb)
from diffcloth_gym.optim import shapes
from diffcloth_gym.optim.tasks_design import apex_angle, twirl
from diffcloth_gym.optim.tasks_meshes import MESHES, write_all
from diffcloth_gym.scenes import CONFIG_DIR

# Short versions: (builder keyword arguments, a point inside the box as a fraction of it).
SMALL = {
    "sphere": {"steps": 60, "rows": 9},
    "wind": {"steps": 30, "rows": 6},
    "tshirt": {"steps": 25},
    "flag": {"steps": 25},
    "dress": {"steps": 30},
    "hat": {"steps": 12},
    "sock": {"steps": 20},
}


#: Central-difference step as a fraction of each parameter's range: small enough for the
#: contact set to stay put, large enough that the forward solve's residual (tolerance 1e-11)
#: does not swamp the difference (the dress's loss is a small difference of hem heights).
EPS = {"dress": 1e-4}
#: Where the gradient is checked, as the spread of a seeded start around the box's middle. The
#: sock's and hat's random trajectories fling the cloth into flapping self-contact within 20
#: steps (gradcheck lists hundreds of contacts switching between the +eps and -eps runs): they
#: are checked near the still trajectory, where the contact set holds.
SPREAD = {"hat": 0.02, "sock": 0.02}


def test_every_task_has_a_small_version():
    assert set(SMALL) == set(TASKS)


@pytest.mark.parametrize("name", sorted(SMALL))
def test_task_builds_and_its_gradient_matches_central_differences(name):
    if name in ("hat", "sock"):
        pytest.importorskip("torch")
    task = TASKS[name](**SMALL[name])
    lo, hi = task.param.bounds
    assert task.param.size == len(task.param.names) == len(lo) and np.all(lo < hi)
    if task.truth is not None:
        assert task.truth.shape == (task.param.size,) and np.all((lo <= task.truth) & (task.truth <= hi))
    obj = task.objective()
    theta = obj.from_unit(initial_guess(task.param, seed=3, spread=SPREAD.get(name, 0.4)))
    # Up to 5 entries (the splines' 18 and 36 take long): spread over the vector.
    idx = np.unique(np.linspace(0, task.param.size - 1, min(task.param.size, 5)).round().astype(int))
    rep = gradcheck(obj, theta, indices=idx, eps=EPS.get(name, 1e-5) * (hi - lo))
    assert rep.grad_max > 0 and np.isfinite(rep.loss)
    # A wrong chain rule or a missing term would be off by O(1) of the largest entry.
    assert rep.max_error < 1e-4, str(rep)
    if task.truth is not None:
        # The target motion is the truth's rollout at the same preset: loss 0 there.
        assert obj.loss(task.truth) == pytest.approx(0.0, abs=1e-9)


def test_sphere_identification_recovers_mu_on_a_tiny_cloth():
    task = TASKS["sphere"](steps=80, rows=9)
    obj = task.objective()
    assert task.truth.tolist() == [0.3]
    run = run_lbfgsb(obj, obj.to_unit([0.55]), budget=3000, show_progress=False)
    assert run.best_loss < 1e-3 * run.initial_loss
    assert run.best_theta[0] == pytest.approx(0.3, abs=2e-3)


def test_wind_identification_recovers_the_wind_on_a_small_napkin():
    task = TASKS["wind"](steps=60, rows=6)
    obj = task.objective()
    start = task.truth + np.array([0.1, -0.05, -0.1, 0.8, 0.3])
    run = run_lbfgsb(obj, obj.to_unit(start), budget=12000, show_progress=False)
    assert run.best_loss < 1e-4 * run.initial_loss, run.stop
    np.testing.assert_allclose(run.best_theta, task.truth, atol=1e-2)


def test_dress_measures_the_apex_angle_of_its_rest_cone_and_twirls_the_waist():
    task = TASKS["dress"](steps=5)
    rest = task.sim.rest_positions
    waist, hem = task.extra["waist"], task.extra["hem"]
    # The rest skirt flares at 60 degrees from the vertical: apex angle 120.
    assert apex_angle(rest, waist, hem) == pytest.approx(120.0, abs=1e-6)
    assert task.extra["target_height"] == pytest.approx(-3.0 * math.cos(math.radians(50.0)))
    t = twirl(rest[waist], steps=50, h=0.01, omega=2.0, ramp=0.2)
    # Radius and height kept; angle reached = omega (t - ramp / 2) after the ramp.
    np.testing.assert_allclose(np.linalg.norm(t[:, :, [0, 2]], axis=2), 1.0, atol=1e-12)
    ang = math.atan2(-t[-1, 0, 2], t[-1, 0, 0])
    assert ang == pytest.approx(2.0 * (0.5 - 0.1), abs=1e-12)


def test_shipped_task_meshes_are_what_the_generators_make(tmp_path):
    for path in write_all(tmp_path):
        assert path.read_text() == (CONFIG_DIR / path.name).read_text(), path.name
    assert set(MESHES) == {"dress_skirt.obj", "tshirt_tube.obj"}


def test_flat_tube_is_two_layers_held_at_its_sides():
    v, t, sets = shapes.flat_tube(around=16, rings=4, width=2.0, gap=0.2)
    assert v.shape == (64, 3) and t.shape == (2 * 3 * 16, 3)
    left, right = sets["shoulders"]
    assert v[left, 0] == pytest.approx(-1.0) and v[right, 0] == pytest.approx(1.0)
    assert np.all(np.abs(v[:, 2]) <= 0.1 + 1e-12)
    # Every edge of the top ring is used once (open top), every interior edge twice.
    edges = {}
    for tri in t:
        for a, b in ((tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0])):
            key = (min(a, b), max(a, b))
            edges[key] = edges.get(key, 0) + 1
    assert sorted(set(edges.values())) == [1, 2]


@pytest.mark.parametrize("call, name", [
    (lambda: shapes.skirt(around=2), "around"),
    (lambda: shapes.skirt(half_angle_deg=95), "half_angle_deg"),
    (lambda: shapes.skirt(length=-1), "length"),
    (lambda: shapes.flat_tube(around=15), "around"),
    (lambda: shapes.flat_tube(gap=5.0), "gap"),
    (lambda: TASKS["dress"](target_deg=200), "target_deg"),
    (lambda: TASKS["wind"](steps=0), "steps"),
    (lambda: HeightMatch([], 0.0), "nodes"),
    (lambda: GroupKeypoints([1, 2], np.zeros((1, 3))), "groups"),
    (lambda: Fixed(targets=np.zeros((3, 2))), "targets"),
])
def test_bad_task_arguments_raise_input_errors_naming_them(call, name):
    with pytest.raises(InputError, match=name):
        call()


def test_height_and_group_keypoint_losses_match_finite_differences():
    rng = np.random.default_rng(0)
    xs = rng.normal(size=(3, 10, 3))
    losses = [HeightMatch([1, 4, 7], 0.3), GroupKeypoints([[0, 1], [5, 9]], rng.normal(size=(2, 3)), step=1)]
    for loss in losses:
        _, g = loss(xs)
        full = np.zeros_like(xs)
        for k, a in g.items():
            full[k] += a
        num = np.zeros_like(xs)
        for i in np.ndindex(xs.shape):
            e = np.zeros_like(xs)
            e[i] = 1e-6
            num[i] = (loss(xs + e)[0] - loss(xs - e)[0]) / 2e-6
        np.testing.assert_allclose(full, num, atol=1e-7)


def test_fixed_inputs_stack_beside_physical_parameters():
    task = TASKS["dress"](steps=4)
    param = task.param
    assert isinstance(param, Stack) and param.size == 2
    inp = param.inputs(np.array([0.3, 0.3]), 4)
    assert inp.targets.shape == (4, 24, 3) and inp.params == {"density": 0.3, "k_bend": 0.3}
    with pytest.raises(InputError, match="targets"):
        Stack([PhysicalParams(task.sim, {"density": (0.1, 1.0)}), Fixed(targets=np.zeros((2, 24, 3)))]).inputs(
            np.array([0.3]), 4)


def test_cmaes_runs_on_a_one_parameter_task():
    from diffcloth_gym.optim import run_cmaes

    # cma 4.x raised "not yet initialized (dimension needed)" at its first tell in 1-D.
    task = TASKS["sphere"](steps=60, rows=9)
    obj = task.objective()
    run = run_cmaes(obj, obj.to_unit([0.7]), budget=1200, show_progress=False)
    assert run.steps_used <= 1200 and run.evaluations >= 10 and run.best_loss < 0.5 * run.initial_loss
