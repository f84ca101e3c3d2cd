"""The Python API: construction, stepping, physical sanity, errors, GIL release, profile."""

import copy
import threading
import warnings

import numpy as np
import pytest

import diffcloth_gym
from diffcloth_gym import Simulator
from tests.conftest import SMALL_GRID


def test_every_shipped_scene_builds_and_steps():
    for name in diffcloth_gym.scene_names():
        sim = Simulator.from_config(name)
        stats = sim.step(steps=2)
        assert stats["iterations"] >= 1
        assert np.isfinite(sim.positions).all()


def test_arrays_are_float64_n_by_3(wind):
    for a in (wind.positions, wind.velocities, wind.rest_positions):
        assert a.dtype == np.float64 and a.shape == (wind.num_nodes, 3)
    assert wind.triangles.shape[1] == 3 and wind.triangles.max() < wind.num_nodes
    assert wind.masses.shape == (wind.num_nodes,)
    assert wind.effects == ["gravity", "stretch", "attachments", "wind"]


def test_free_fall_closed_form_from_python():
    cfg = {"h": 0.02, "effects": ["gravity"], "material": {"density": 1.0},
           "mesh": {"kind": "grid", "rows": 3, "cols": 3, "width": 1, "height": 1, "plane": "xz"}}
    sim = Simulator.from_config(cfg)
    x0 = sim.positions
    v0 = np.tile([1.0, 2.0, -0.5], (sim.num_nodes, 1))
    sim.reset(v=v0)
    sim.step(steps=10)
    n, h, g = 10, 0.02, np.array([0, -9.8, 0])
    expected = x0 + n * h * v0 + h * h * g * n * (n + 1) / 2
    np.testing.assert_allclose(sim.positions, expected, atol=1e-10)
    assert sim.time == pytest.approx(0.2)


def test_end_effectors_move_the_cloth(small):
    targets = small.attachment_targets + np.array([0.0, 0.0, 0.3])
    for _ in range(100):
        small.step(attachment_targets=targets)
    nodes = small.attachment_nodes
    np.testing.assert_allclose(small.positions[nodes], targets, atol=5e-3)


def test_set_params_and_solver(wind):
    wind.set_params(k_stretch=250.0, gravity=[0, -5, 0])
    assert wind.params()["k_stretch"] == 250.0
    assert wind.profile()["refactorizations"] == 1
    wind.set_solver(tolerance=1e-6, acceleration="none", max_iterations=50)
    assert wind.solver()["acceleration"] == "none"
    stats = wind.step()
    assert stats["iterations"] <= 50


def test_newton_polish_is_a_solver_setting(wind):
    assert wind.solver()["polish"] == "none"
    wind.set_solver(polish="newton", tolerance=1e-10, max_iterations=2000)
    assert wind.solver()["polish"] == "newton"
    for _ in range(5):
        assert wind.step()["converged"]
    assert wind.profile()["newton_steps"] > 0
    with pytest.raises(diffcloth_gym.ParameterError, match="polish"):
        wind.set_solver(polish="lbfgs")
    assert wind.solver()["polish"] == "newton"


@pytest.mark.parametrize(
    "mutate, needle",
    [
        (lambda c: c["material"].update(k_strech=1.0), "k_strech"),
        (lambda c: c.update(colour="red"), "colour"),
        (lambda c: c["material"].update(k_stretch=-5.0), "k_stretch"),
        (lambda c: c["mesh"].update(rows=1), "2x2"),
        (lambda c: c["effects"].append("magic"), "magic"),
        (lambda c: c.pop("attachments"), "[attachments]"),
        (lambda c: c.update(mesh={"kind": "obj", "path": "/nonexistent.obj"}), "nonexistent.obj"),
    ],
)
def test_bad_configs_raise_value_errors_naming_the_problem(mutate, needle):
    cfg = copy.deepcopy(SMALL_GRID)
    mutate(cfg)
    with pytest.raises(ValueError, match=None) as err:
        Simulator.from_config(cfg)
    assert needle in str(err.value)
    assert isinstance(err.value, diffcloth_gym.DiffClothError)


def _with(mutate):
    cfg = copy.deepcopy(SMALL_GRID)
    mutate(cfg)
    return lambda tmp_path: Simulator.from_config(cfg)


def _obj_with_a_bad_face(tmp_path):
    path = tmp_path / "bad.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n")
    return Simulator.from_config({"h": 0.01, "effects": [], "material": {"density": 1.0},
                                  "mesh": {"kind": "obj", "path": str(path)}})


def _on_small(call):
    return lambda tmp_path: call(Simulator.from_config(SMALL_GRID))


@pytest.mark.parametrize(
    "cause, error",
    [
        # Core errors, each mapped by the binding to its class.
        (_with(lambda c: c.update(colour="red")), diffcloth_gym.ConfigError),
        (_with(lambda c: c.update(mesh={"kind": "obj", "path": "/nonexistent.obj"})), diffcloth_gym.ConfigError),
        (_with(lambda c: c["mesh"].update(rows=1)), diffcloth_gym.MeshError),
        (_obj_with_a_bad_face, diffcloth_gym.MeshError),
        (_on_small(lambda s: s._core.step(np.zeros((5, 3)), None, 1)), diffcloth_gym.InputError),
        (_on_small(lambda s: s.set_params(k_stretch=-1.0)), diffcloth_gym.ParameterError),
        (_on_small(lambda s: s.set_params(h=1e-200) or s.step()), diffcloth_gym.DivergedError),
        # The binding's own checks.
        (_on_small(lambda s: s._core.reset(np.zeros((3, 2)), None)), diffcloth_gym.InputError),
        (_on_small(lambda s: s.obstacle_distance(0)), diffcloth_gym.InputError),
        (_on_small(lambda s: s.set_params(stiffness=1.0)), diffcloth_gym.ParameterError),
        (_on_small(lambda s: s.set_solver(acceleration="newton")), diffcloth_gym.ParameterError),
        (_on_small(lambda s: s.set_recording(True, checkpoint_every=0)), diffcloth_gym.ParameterError),
        # The Python wrapper's checks.
        (_on_small(lambda s: s.step(attachment_targets=np.zeros((2, 2)))), diffcloth_gym.InputError),
    ],
    ids=["unknown config key", "missing mesh file", "grid below 2x2", "obj face out of range",
         "targets row count", "negative stiffness", "diverging step", "reset shape", "no such obstacle",
         "unknown parameter", "unknown acceleration", "checkpoint_every 0", "wrapper targets shape"],
)
def test_each_error_is_raised_with_its_class(tmp_path, cause, error):
    with pytest.raises(error) as err:
        cause(tmp_path)
    assert type(err.value) is error
    bad_input = issubclass(error, diffcloth_gym.errors.InvalidInputError)
    assert isinstance(err.value, ValueError) == bad_input


def test_a_diverged_step_is_rolled_back_and_the_simulator_stays_usable(small):
    small.step()
    before = small.positions
    small.reset(x=before, v=np.full((small.num_nodes, 3), 1e200))
    with pytest.raises(diffcloth_gym.DivergedError, match="diverged"):
        small.step()
    np.testing.assert_array_equal(small.positions, before)
    small.reset()
    small.step()
    assert np.isfinite(small.positions).all()


def test_unknown_scene_name_lists_the_shipped_ones():
    with pytest.raises(diffcloth_gym.ConfigError, match="wind"):
        Simulator.from_config("no_such_scene")


def test_bad_step_input_raises_and_simulator_stays_usable(small):
    before = small.positions
    n, k = small.num_nodes, len(small.attachment_nodes)
    bad_inputs = [
        dict(attachment_targets=np.zeros((k + 1, 3))),
        dict(attachment_targets=np.zeros((k, 2))),
        dict(attachment_targets=np.full((k, 3), np.nan)),
        dict(external_forces=np.zeros(n)),
        dict(external_forces=np.full((n, 3), np.inf)),
        dict(external_forces=[["a", "b", "c"]] * n),
        dict(steps=0),
    ]
    for kwargs in bad_inputs:
        with pytest.raises(ValueError):
            small.step(**kwargs)
    np.testing.assert_array_equal(small.positions, before)
    with pytest.raises(ValueError, match="k_stretch"):
        small.set_params(k_stretch=-1.0)
    with pytest.raises(ValueError, match="unknown parameter"):
        small.set_params(stiffness=3.0)
    with pytest.raises(ValueError, match="tolerance"):
        small.set_solver(tolerance=float("nan"))
    with pytest.raises(ValueError, match="x"):
        small.reset(x=np.zeros((3, 3)))
    small.step(external_forces=np.zeros((n, 3)))
    assert np.isfinite(small.positions).all()


def test_external_forces_need_the_effect(wind):
    with pytest.raises(diffcloth_gym.InputError, match="external_forces"):
        wind.step(external_forces=np.zeros((wind.num_nodes, 3)))


def test_profile_accounts_for_the_step_time(wind):
    wind.reset_profile()
    wind.step(steps=20)
    p = wind.profile()
    assert p["steps"] == 20 and p["iterations"] >= 20
    parts = p["local_s"] + p["global_s"] + p["other_s"]
    assert parts == pytest.approx(p["total_s"], rel=1e-6)
    assert p["local_s"] > 0 and p["global_s"] > 0


def test_long_steps_release_the_gil():
    """While one thread is inside a long Rust call, another Python thread keeps running."""
    sim = Simulator.from_config("wind")
    sim.set_solver(tolerance=0.0, max_iterations=200)
    done = threading.Event()
    ticks = 0

    def work():
        sim.step(steps=60)
        done.set()

    t = threading.Thread(target=work)
    t.start()
    while not done.is_set():
        ticks += 1
    t.join()
    # With the GIL held for the whole call, the main thread could only tick before/after it.
    assert ticks > 10_000


def test_write_obj_round_trip(tmp_path, wind):
    wind.step(steps=5)
    path = tmp_path / "state.obj"
    wind.write_obj(path)
    sim = Simulator.from_config({"h": 0.01, "effects": [], "material": {"density": 1.0},
                                 "mesh": {"kind": "obj", "path": str(path)}})
    np.testing.assert_allclose(sim.rest_positions, wind.positions, rtol=0, atol=1e-12)


def test_trace_has_one_row_per_iteration_and_energy_never_rises(small):
    small.set_trace(True)
    small.reset(v=np.random.default_rng(3).normal(0, 0.5, (small.num_nodes, 3)))
    stats = small.step()
    trace = small.trace()
    assert trace.shape == (stats["iterations"], 2)
    assert trace[-1, 1] == pytest.approx(stats["residual"])
    assert np.all(np.diff(trace[:, 0]) <= 1e-12 * np.abs(trace[:-1, 0]))
    small.set_trace(False)
    small.step()
    assert small.trace().shape == (0, 2)


def test_a_step_stopped_at_the_cap_warns_unless_the_count_is_fixed():
    sim = Simulator.from_config("wind")
    sim.set_solver(max_iterations=2, tolerance=1e-12)
    with pytest.warns(diffcloth_gym.ConvergenceWarning, match="iteration cap"):
        sim.step(steps=3)
    sim.set_solver(tolerance=0.0)  # a fixed iteration count: nothing to warn about
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        sim.step()


def test_one_table_of_parameter_names(small):
    """params(), set_params, the gradients and torch's PARAM_NAMES share the core's table."""
    from diffcloth_gym import _core

    names = set(small.params())
    # mu_self exists only in scenes with self-collision (this one has none).
    assert "mu_self" not in names and names | {"mu_self"} == set(_core.PARAM_NAMES) | {"h"}
    small.set_params(**small.params())  # every name is settable
    small.set_recording(True)
    small.step()
    g = small.backward(dl_dx=np.ones((1, small.num_nodes, 3)))
    assert set(_core.PARAM_NAMES) <= set(g)


def test_sizes_that_would_exhaust_memory_are_refused(small):
    """Issue 11 item 2: a number that sizes an allocation is bounded, with an error naming it,
    and the simulator stays usable (these aborted the interpreter before)."""
    before = small.positions.copy()
    with pytest.raises(diffcloth_gym.ParameterError, match="max_iterations must be at most"):
        small.set_solver(max_iterations=2**40)
    small.set_trace(True)
    small.step()
    assert np.all(np.isfinite(small.positions)) and not np.array_equal(small.positions, before)
    huge = {**SMALL_GRID, "mesh": {**SMALL_GRID["mesh"], "rows": 100_000, "cols": 100_000}}
    with pytest.raises(diffcloth_gym.MeshError, match="larger than"):
        Simulator.from_config(huge)
    for path in ("/dev/zero", "/dev/urandom"):
        obj = {**SMALL_GRID, "mesh": {"kind": "obj", "path": path}}
        with pytest.raises(diffcloth_gym.ConfigError, match="not a regular file"):
            Simulator.from_config(obj)


def test_ctrl_c_interrupts_a_long_step_call():
    """Issue 11 item 3 (the step half): SIGINT during step(steps=N) raises KeyboardInterrupt
    at the last completed step; before, the call ran on for the whole N."""
    import signal
    import subprocess
    import sys
    from pathlib import Path

    script = (
        "from diffcloth_gym import Simulator\n"
        "s = Simulator.from_config('wind')\n"
        "print('ready', flush=True)\n"
        "try:\n"
        "    s.step(steps=10**7)\n"
        "except KeyboardInterrupt:\n"
        "    print('interrupted', round(s.time / s.params()['h']), flush=True)\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True,
                            cwd=Path(__file__).resolve().parent.parent)
    assert proc.stdout.readline().strip() == "ready"
    import time
    time.sleep(0.5)
    proc.send_signal(signal.SIGINT)
    # 10**7 steps take hours: finishing at all within the timeout means the signal was seen.
    out, _ = proc.communicate(timeout=60)
    words = out.split()
    assert words[0] == "interrupted", out
    assert 0 < int(words[1]) < 10**7


def test_ctrl_c_interrupts_a_long_backward_call():
    """Issue 11 item 3 (the backward half): SIGINT during backward() raises KeyboardInterrupt
    within a second and leaves the simulator (state, tape) as it was; before, the adjoint
    replay ran to its end (here about 3 s of direct solves; a long tape ran for minutes)."""
    import signal
    import subprocess
    import sys
    import time
    from pathlib import Path

    script = (
        "import numpy as np\n"
        "from diffcloth_gym import Simulator, load_scene\n"
        "s = Simulator.from_config(load_scene('wind', rows=24, cols=24))\n"
        "s.set_solver(tolerance=1e-6)\n"
        "s.set_recording(True, checkpoint_every=50)\n"
        "s.step(steps=200)\n"
        "x, tape = s.positions, s.tape_info()\n"
        "dl = np.ones((200, s.num_nodes, 3))\n"
        "print('ready', flush=True)\n"
        "try:\n"
        "    s.backward(dl_dx=dl, solver='direct')\n"
        "    print('finished', flush=True)\n"
        "except KeyboardInterrupt:\n"
        "    same = (s.positions == x).all() and s.tape_info() == tape\n"
        "    print('interrupted', same, flush=True)\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True,
                            cwd=Path(__file__).resolve().parent.parent)
    try:
        assert proc.stdout.readline().strip() == "ready"
        time.sleep(0.3)
        proc.send_signal(signal.SIGINT)
        sent = time.perf_counter()
        line = proc.stdout.readline().split()
        latency = time.perf_counter() - sent
    finally:
        proc.kill()
        proc.communicate()
    assert line == ["interrupted", "True"], line
    assert latency < 1.0, f"backward returned {latency:.2f} s after SIGINT"


@pytest.mark.parametrize("call", [
    lambda s: s._core.obstacle_distance(-1),
    lambda s: s._core.set_obstacle_mu(-1, 0.1),
    lambda s: s.set_recording(True, checkpoint_every=-1),
    lambda s: s._core.step(None, None, 10**30),
    lambda s: s._core.step(None, None, -3),
    lambda s: s.backward(dl_dx=None, max_iterations=-1),
])
def test_bad_integers_raise_input_errors_naming_the_argument(small, call):
    """Issue 11 item 6 (part): negative or oversized integers raised OverflowError."""
    small.set_recording(True)
    small.step()
    with pytest.raises(diffcloth_gym.InputError, match="must be a non-negative integer"):
        call(small)
    small.step()


def test_wrong_types_raise_errors_naming_the_argument(small):
    """Issue 11 item 6 (part): these raised TypeError."""
    with pytest.raises(diffcloth_gym.ConfigError, match="config must be"):
        Simulator.from_config(None)
    with pytest.raises(diffcloth_gym.ParameterError, match="mu must be a number"):
        small._core.set_self_mu(None)
