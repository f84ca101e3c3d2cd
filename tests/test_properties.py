"""Property-based tests (hypothesis) over the public Python API (issue 11).

Two properties, over random configs, arrays (NaN, inf, huge, wrong shapes, wrong types) and
call sequences:

1. every call either succeeds and leaves a finite state, or raises a
   :mod:`diffcloth_gym.errors` exception (never a bare ``TypeError``/``OverflowError``, a
   ``PanicException`` or a crash);
2. a simulator whose call raised is indistinguishable from a twin that never saw the call:
   same positions, velocities, time, targets, parameters, solver settings and tape, bit for
   bit, and the same results from the same later calls.

Sized for CI (a few hundred examples in all, derandomized: the same examples every run);
``pytest --full`` runs ten times as many.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, invariant, rule

from diffcloth_gym import Simulator
from diffcloth_gym.errors import ConvergenceWarning, DiffClothError

from . import conftest


def examples(n: int) -> settings:
    """CI-sized settings for n examples (ten times as many with --full)."""
    return settings(max_examples=n * (10 if conftest.FULL else 1), derandomize=True, deadline=None,
                    database=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


# -- values ------------------------------------------------------------------------------
WEIRD = [math.nan, math.inf, -math.inf, 1e300, -1e300, 0.0, -0.0, 1e-300, -1.0, 2**63, -(2**70)]
JUNK = [None, "x", "1.0", [], [1.0, 2.0], {"a": 1}, b"\x00", object()]

finite = st.floats(-10.0, 10.0, allow_nan=False)
weird = st.sampled_from(WEIRD)
number = st.one_of(finite, weird)
anything = st.one_of(number, st.integers(-(2**70), 2**70), st.sampled_from(JUNK), st.booleans())


def node_array(rows: int, scale: float = 1.0):
    """Mostly well-formed (rows, 3) arrays, some with bad entries, some of the wrong shape or
    type."""
    good = st.lists(st.tuples(finite, finite, finite), min_size=rows, max_size=rows).map(
        lambda r: scale * np.array(r, dtype=float).reshape(rows, 3))

    def spoil(a, i, v):
        a = a.copy()
        if a.size:
            a.flat[i % a.size] = v
        return a
    bad_entry = st.builds(spoil, good, st.integers(0, 3 * rows), weird)
    bad_shape = st.sampled_from([(rows + 1, 3), (rows, 2), (3,), (1, rows, 3), (0, 3)]).map(np.zeros)
    return st.one_of(good, good, bad_entry, bad_shape, st.sampled_from(JUNK[1:]))


def call_or_error(f, *args, **kwargs):
    """(True, result) or (False, exception) for a diffcloth error; anything else fails."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        try:
            return True, f(*args, **kwargs)
        except DiffClothError as e:
            return False, e


def assert_finite_state(sim: Simulator) -> None:
    assert np.isfinite(sim.positions).all() and np.isfinite(sim.velocities).all()
    assert math.isfinite(sim.time)


# -- 1. random configs -------------------------------------------------------------------
EFFECTS = ["gravity", "stretch", "bend", "attachments", "wind", "external_forces", "obstacle_contact",
           "friction", "self_collision"]


@st.composite
def valid_configs(draw) -> dict:
    """Small grid scenes with any subset of the effects, their tables and a placement."""
    size = st.integers(2, 5)
    rows, cols = draw(size), draw(size)
    cfg = {
        "h": draw(st.sampled_from([0.01, 0.005, 0.05, 0.5])),
        "effects": draw(st.lists(st.sampled_from(EFFECTS), unique=True, max_size=9)),
        "mesh": {"kind": "grid", "rows": rows, "cols": cols, "width": draw(st.floats(0.1, 3.0)),
                 "height": draw(st.floats(0.1, 3.0)), "plane": draw(st.sampled_from(["xy", "xz"]))},
        "material": {"density": draw(st.floats(0.01, 2.0)), "k_stretch": draw(st.floats(0.0, 1e3)),
                     "k_bend": draw(st.floats(0.0, 1.0))},
        "placement": {"scale": draw(st.floats(0.1, 10.0)),
                      "rotate_deg": draw(st.tuples(finite, finite, finite).map(list)),
                      "translate": draw(st.tuples(finite, finite, finite).map(list))},
        "attachments": draw(st.one_of(
            st.just({"select": "top_corners"}),
            st.fixed_dictionaries({"nodes": st.lists(st.integers(0, rows * cols - 1), unique=True, min_size=1,
                                                     max_size=3), "stiffness": st.floats(1.0, 1e4)}))),
        "wind": {"direction": draw(st.tuples(finite, finite, finite).map(list)), "omega": draw(finite)},
        "obstacles": draw(st.lists(st.fixed_dictionaries({
            "shape": st.one_of(
                st.fixed_dictionaries({"kind": st.just("plane"), "point": st.just([0.0, -0.5, 0.0]),
                                       "normal": st.just([0.0, 1.0, 0.0])}),
                st.fixed_dictionaries({"kind": st.just("sphere"), "center": st.just([0.0, -1.0, 0.0]),
                                       "radius": st.floats(0.1, 1.0)})),
            "mu": st.floats(0.0, 1.0)}), max_size=2)),
        "self_collision": {"radius": draw(st.floats(0.001, 0.1))},
    }
    # A table without its effect (or the reverse) is refused: keep them consistent.
    effects = cfg["effects"]
    for key, effect in [("attachments", "attachments"), ("wind", "wind"), ("obstacles", "obstacle_contact"),
                        ("self_collision", "self_collision")]:
        if effect not in effects:
            del cfg[key]
    if "obstacle_contact" in effects and not cfg["obstacles"]:
        effects.remove("obstacle_contact")
        del cfg["obstacles"]
    return cfg


def leaves(cfg, path=()):
    """Every (path, value) of a nested config."""
    items = cfg.items() if isinstance(cfg, dict) else enumerate(cfg) if isinstance(cfg, list) else ()
    for k, v in items:
        yield path + (k,), v
        yield from leaves(v, path + (k,))


@st.composite
def configs(draw) -> dict:
    """A valid config, or one with one entry replaced by junk, a weird number, removed, or an
    unknown key added."""
    cfg = draw(valid_configs())
    how = draw(st.sampled_from(["valid", "valid", "replace", "remove", "add"]))
    if how == "valid":
        return cfg
    path = draw(st.sampled_from([p for p, _ in leaves(cfg)]))
    parent = cfg
    for k in path[:-1]:
        parent = parent[k]
    if how == "replace":
        parent[path[-1]] = draw(st.one_of(anything, st.integers(-3, 10**12)))
    elif how == "remove":
        del parent[path[-1]]
    elif isinstance(parent, dict):
        parent["colour"] = 1
    return cfg


@examples(120)
@given(cfg=configs(), targets=node_array(2), forces=st.one_of(st.none(), node_array(25, 0.1)))
def test_any_config_builds_a_working_simulator_or_raises_a_config_error(cfg, targets, forces):
    ok, sim = call_or_error(Simulator.from_config, cfg)
    event("built" if ok else f"refused: {type(sim).__name__}")
    if not ok:
        return
    assert_finite_state(sim)
    for _ in range(2):
        ok, _ = call_or_error(sim.step)
        assert_finite_state(sim)
    call_or_error(sim.step, attachment_targets=targets if sim.attachment_nodes else None,
                  external_forces=forces)
    assert_finite_state(sim)


# -- 2. random call sequences against an untouched twin -----------------------------------
TWIN_SCENE = {
    "h": 0.01,
    "effects": ["gravity", "stretch", "bend", "attachments", "external_forces", "obstacle_contact",
                "friction", "self_collision"],
    "mesh": {"kind": "grid", "rows": 4, "cols": 4, "width": 1.0, "height": 1.0, "plane": "xy"},
    "material": {"density": 0.1, "k_stretch": 100.0, "k_bend": 0.01},
    "attachments": {"select": "top_corners"},
    "obstacles": [{"shape": {"kind": "sphere", "center": [0.0, -0.8, 0.3], "radius": 0.5}, "mu": 0.3}],
    "self_collision": {"radius": 0.02},
}
N, K = 16, 2
PARAM_NAMES = ["h", "density", "k_stretch", "k_bend", "k_attach", "gravity", "wind_direction",
               "wind_omega", "wind_phi", "colour"]
SOLVER_KEYS = ["max_iterations", "tolerance", "record_tolerance", "record_max_iterations",
               "acceleration", "history", "parallel", "speed", "polish"]
# Iteration caps beyond a few thousand are valid but would make a step take seconds.
small_int = st.one_of(st.integers(1, 200), st.sampled_from([0, -1, 2**40, 10**7, 2**64]))


def snapshot(sim: Simulator) -> dict:
    """Everything a failed call must leave as it was (the profile may count the failure)."""
    return {"x": sim.positions, "v": sim.velocities, "time": sim.time, "targets": sim.attachment_targets,
            "params": sim.params(), "solver": sim.solver(), "tape": sim.tape_info(),
            "contacts": sim.contacts(), "last_step": sim.last_step()}


def same(a, b) -> bool:
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)) and not (a and isinstance(a[0], (int, float, str))):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (math.isnan(a) and math.isnan(b))
    return a == b


class TwinMachine(RuleBasedStateMachine):
    """Each call goes to `sim`; only the calls that succeed go to `twin` as well. Both must
    stay identical, finite and give identical results."""

    def __init__(self):
        super().__init__()
        self.sim = Simulator.from_config(TWIN_SCENE)
        self.twin = Simulator.from_config(TWIN_SCENE)

    def both(self, call):
        ok, result = call_or_error(call, self.sim)
        event("accepted" if ok else f"refused: {type(result).__name__}")
        if ok:
            ok_twin, twin_result = call_or_error(call, self.twin)
            assert ok_twin, f"the twin raised {twin_result!r} on a call the simulator accepted"
            assert same(result, twin_result), "the same call gave different results"
        return ok

    @rule(goals=st.one_of(st.none(), node_array(K)), forces=st.one_of(st.none(), node_array(N, 0.1)),
          steps=st.one_of(st.integers(1, 3), st.sampled_from([0, -1, 10**30, 1.5, "2", None])))
    def step(self, goals, forces, steps):
        self.both(lambda s: s.step(attachment_targets=goals, external_forces=forces, steps=steps))

    @rule(name=st.sampled_from(PARAM_NAMES), value=st.one_of(
        number, anything, st.tuples(finite, finite, finite).map(list), st.sampled_from([0.005, 0.02, 50.0, 500.0])))
    def set_params(self, name, value):
        self.both(lambda s: s.set_params(**{name: value}))

    @rule(key=st.sampled_from(SOLVER_KEYS), value=st.one_of(
        small_int, number, st.sampled_from(["anderson", "none", "newton", "fast", True, False]), anything))
    def set_solver(self, key, value):
        if key in ("max_iterations", "record_max_iterations") and isinstance(value, int) and 1000 < value <= 10**6:
            return  # valid, but slow
        self.both(lambda s: s.set_solver(**{key: value}))

    @rule(on=st.booleans(), every=st.one_of(st.none(), st.integers(-2, 4), st.sampled_from([2**64, "3"])))
    def set_recording(self, on, every):
        self.both(lambda s: s.set_recording(on, checkpoint_every=every))

    @rule(data=st.data(), solver=st.sampled_from([None, "krylov", "direct", "fixed_point", "lu"]),
          tolerance=st.one_of(st.none(), st.sampled_from([1e-8, 0.0, -1.0, math.nan])),
          max_iterations=st.one_of(st.none(), small_int))
    def backward(self, data, solver, tolerance, max_iterations):
        steps, _ = self.sim.tape_info()
        shape = data.draw(st.sampled_from([(steps, N, 3), (steps, N, 3), (steps + 1, N, 3), (steps, N, 2)]))
        dl_dx = data.draw(st.one_of(st.none(), st.just(np.ones(shape)), st.just(np.full(shape, math.nan)),
                                    st.just(np.full(shape, 1e-3))))

        def call(s):
            g = s.backward(dl_dx=dl_dx, solver=solver, tolerance=tolerance, max_iterations=max_iterations)
            assert np.isfinite(g["x0"]).all() and np.isfinite(g["v0"]).all()
            return {k: g[k] for k in ("x0", "v0", "attachment_targets", "k_stretch", "mu_obstacles")}
        self.both(call)

    @rule(x=st.one_of(st.none(), node_array(N)), v=st.one_of(st.none(), node_array(N)))
    def reset(self, x, v):
        self.both(lambda s: s.reset(x, v))

    @rule(index=st.one_of(st.integers(-1, 2), st.just(2**64)), mu=number)
    def set_obstacle_mu(self, index, mu):
        self.both(lambda s: s.set_obstacle_mu(index, mu))

    @rule(mu=st.one_of(number, st.sampled_from(JUNK)))
    def set_self_mu(self, mu):
        self.both(lambda s: s.set_self_mu(mu))

    @rule(t=number)
    def set_time(self, t):
        def call(s):
            s.time = t
        self.both(call)

    @rule(index=st.one_of(st.integers(-1, 2), st.just(2**64)))
    def obstacle_distance(self, index):
        self.both(lambda s: s.obstacle_distance(index))

    @invariant()
    def twins_match_and_are_finite(self):
        assert_finite_state(self.sim)
        assert same(snapshot(self.sim), snapshot(self.twin))


TwinMachine.TestCase.settings = examples(40)
TwinMachine.TestCase.settings = settings(TwinMachine.TestCase.settings, stateful_step_count=15)
test_call_sequences_leave_a_failed_simulator_equal_to_its_untouched_twin = TwinMachine.TestCase


def test_a_diverged_step_leaves_the_contacts_of_the_last_completed_step():
    """Found by the twin machine: after a DivergedError, contacts() listed the rolled-back
    step's contacts (and disagreed with last_step())."""
    sim, twin = Simulator.from_config(TWIN_SCENE), Simulator.from_config(TWIN_SCENE)
    for s in (sim, twin):
        s.step(steps=3)
    with pytest.raises(DiffClothError):
        sim.step(attachment_targets=[[1e300, 0, 0], [0, 0, 0]])
    assert same(snapshot(sim), snapshot(twin))
