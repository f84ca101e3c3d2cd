"""The hard cases on grids and OBJ meshes: ``case_<name>(size, workdir, **variant) -> dict``
(registered in :data:`benchmarks.stability.runner.CASES`). Each docstring says what the case
runs and checks; the garment cases are in :mod:`benchmarks.stability.garments`."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.stability.builders import (
    GRAVITY,
    SLOPE_DEG,
    corners,
    crumple_config,
    downhill,
    napkin,
    slope_config,
    sliding_distance,
    sphere_config,
    write_grid_obj,
)
from benchmarks.stability.checks import contact_law, momentum_balance_error
from benchmarks.stability.harness import backward, finish, pick, run
from benchmarks.stability.metrics import ENERGY_BOUND, Monitor
from diffcloth_gym import MeshError, Simulator


def case_large_step_pinned(size: str, workdir: Path, h: float) -> dict:
    """A stiff (k_stretch 1e5) 1 m napkin pinned at two adjacent corners swings down under
    gravity with a large step h (1/30 or 1/10 s). Unforced: energy must not grow; Newton's
    second law for the whole cloth must hold every step; it must actually swing down."""
    rows = pick(size, 10, 20)
    steps = round(pick(size, 2.0, 4.0) / h)
    sim = Simulator.from_config(napkin(rows, h=h, k_stretch=1e5, effects=("attachments",),
                                       attachments={"nodes": [0, rows - 1]}))
    mon = Monitor(energy=True)
    com0 = sim.masses @ sim.positions / sim.masses.sum()
    balance = []
    state = {"p": sim.masses @ sim.velocities}

    def check(_: int) -> None:
        balance.append(momentum_balance_error(sim, state["p"]))
        state["p"] = sim.masses @ sim.velocities

    run(sim, mon, steps, after_step=check)
    drop = float(com0[1] - (sim.masses @ sim.positions / sim.masses.sum())[1])
    worst = max(balance, default=math.inf)
    return finish(mon, {
        "momentum_balance": (worst <= 1e-8, f"max |dp/dt - Mg - F_attach| / Mg = {worst:.2e} (bound 1e-8)"),
        "swings_down": (drop > 0.2, f"centre of mass dropped {drop:.3f} m (hanging from an edge: ~0.5 m; bound > 0.2)"),
    }, ENERGY_BOUND, h_s=h)


def case_large_step_sphere(size: str, workdir: Path, h: float, response: str | None = None) -> dict:
    """``sphere.toml`` with stiff material (k_stretch 1e5) and a large step h (1/30 or 1/10 s):
    the cloth falls 0.6 m onto the sphere (friction 0.3, self-collision). Unforced: energy must
    not grow, no node may cross the sphere's surface; impulses stay in the friction cone.
    ``response``: the contact response (``contact.response``; None: the default, ``auto``).
    ``inertia`` alone fails here (its splitting stalls and nodes go through the sphere);
    ``delassus`` holds every iterate to the contact law, and ``auto`` switches to it on the
    steps that stall on these stiff contacts.
    Full size: 25 x 25 nodes at h = 1/30, 15 x 15 at h = 1/10, where the self-collision
    candidates (reach ``radius + margin + 2 h (|v_a| + |v_b|)``, absolute speeds) grow to
    ~1e5 pairs of the 625 nodes and a step costs a minute."""
    rows = pick(size, 10, 25 if h < 0.05 else 15)
    steps = round(pick(size, 1.5, 3.0) / h)
    cfg = sphere_config(0.3, rows, h=h, k_stretch=1e5)
    if response is not None:
        cfg["contact"]["response"] = response
    sim = Simulator.from_config(cfg)
    mon = Monitor(energy=True)
    cone = []
    state = {"x": sim.positions}

    def check(_: int) -> None:
        cone.append(contact_law(sim, state["x"])["cone"])
        state["x"] = sim.positions

    run(sim, mon, steps, after_step=check)
    worst = max(cone, default=-math.inf)
    return finish(mon, {
        "friction_cone": (worst <= 1e-9, f"max (|J_T| - mu J_n) / max J_n = {worst:.2e} (bound 1e-9)"),
        "lands": (mon.obstacle_contacts > 0, f"{mon.obstacle_contacts} active obstacle contacts"),
    }, ENERGY_BOUND, h_s=h)


def case_large_step_slope(size: str, workdir: Path, h: float) -> dict:
    """``slope.toml`` with stiff material (k_stretch 1e5), mu 0.5 and a large step h: the
    ribbon slides rigidly, so its downhill travel is the implicit-Euler closed form
    ``g (sin - mu cos) h^2 N (N + 1) / 2``."""
    rows = pick(size, 12, 24)
    steps = round(pick(size, 2.0, 4.0) / h)
    sim = Simulator.from_config(slope_config(0.5, rows, h=h, k_stretch=1e5))
    x0 = sim.positions
    mon = Monitor(energy=True)
    run(sim, mon, steps)
    travel = (sim.positions - x0) @ downhill()
    expected = sliding_distance(0.5, h, mon.steps)
    err = float(np.max(np.abs(travel - expected)) / expected)
    return finish(mon, {
        "closed_form_travel": (err <= 1e-6, f"travel {travel.mean():.6f} m vs {expected:.6f} m, max rel. error {err:.1e} (bound 1e-6)"),
    }, ENERGY_BOUND, h_s=h)


def case_soft_hanging(size: str, workdir: Path) -> dict:
    """A very soft napkin (k_stretch 1 N/m, strain limits [0.9, 1.1]) hanging from its top
    corners bounces under gravity. PD strain limiting is a penalty of weight k_stretch * area
    towards the limited stretches, not a hard constraint, so at k_stretch = 1 the limits do not
    bound the stretch (the corner triangles carry the weight at stretch ~3-50). What does bound
    it is energy: a triangle's elastic energy ``k A (s - s_max)^2 / 2`` cannot exceed the total
    ``E(0)``, so ``s <= s_max + sqrt(2 E(0) / (k A_min))``. Checked, with the energy bound and
    Newton's second law for the whole cloth."""
    rows = pick(size, 10, 20)
    steps = pick(size, 200, 1000)
    k, limits = 1.0, (0.9, 1.1)
    sim = Simulator.from_config(napkin(rows, plane="xy", k_stretch=k, k_bend=1e-4, strain_limits=limits,
                                       effects=("attachments",), attachments={"select": "top_corners"}))
    mon = Monitor(energy=True)
    balance = []
    state = {"p": sim.masses @ sim.velocities}

    def check(_: int) -> None:
        balance.append(momentum_balance_error(sim, state["p"]))
        state["p"] = sim.masses @ sim.velocities

    e0 = sim.mechanical_energy()
    mass = float(sim.masses.sum())
    heights = [float(sim.positions[:, 1].min())]
    run(sim, mon, steps, after_step=lambda k_: (check(k_), heights.append(float(sim.positions[:, 1].min()))))
    tri = sim.triangles
    x = sim.rest_positions
    area_min = float(np.min(0.5 * np.linalg.norm(np.cross(x[tri[:, 1]] - x[tri[:, 0]], x[tri[:, 2]] - x[tri[:, 0]]), axis=1)))
    energy0 = e0 - mass * GRAVITY * min(heights)  # E(0) above the lowest height of the run
    bound = limits[1] + math.sqrt(2 * energy0 / (k * area_min))
    worst = max(balance, default=math.inf)
    return finish(mon, {
        "momentum_balance": (worst <= 1e-8, f"max |dp/dt - Mg - F_attach| / Mg = {worst:.2e} (bound 1e-8)"),
        "energy_bounds_stretch": (mon.max_stretch <= bound, f"max stretch {mon.max_stretch:.2f} <= {bound:.2f} = s_max + sqrt(2 E0 / (k A_min))"),
    }, ENERGY_BOUND)


def case_fast_end_effectors(size: str, workdir: Path) -> dict:
    """A 1 m napkin (k_stretch 1e4, strain limits [0.95, 1.05], no gravity: the end effectors
    are the only load) held at its four corners. First the corners are pulled apart within 2
    steps until the cloth is uniformly at its strain limit (corner distances x 1.05) and held:
    all stretches must then lie within the limits +- 1e-3 and the cloth must be at its limit (min
    stretch >= 1.05 - 1e-3). (With gravity the corner triangles carry the sag as a point load:
    their stretch exceeds the limit by an amount that grows with mesh refinement.) Then the end effectors jump 0.5 m per step: 20 steps of random rigid
    moves of the stretched shape, 10 steps in which each corner jumps 0.5 m on its own, and a
    hold. Forced (no energy bound); states must stay finite (the stretch during the jumps is
    reported as ``fast_max_stretch``: PD strain limiting is a penalty and inertia wins at
    50 m/s) and the corners must end at their targets. (The strain check is not repeated after
    the jumps: they can leave a fold in the free edges that tension along the edge cannot
    undo, a stable state.) Backward through the whole motion (loss on the final state)."""
    rows = pick(size, 10, 20)
    hold = pick(size, 100, 300)
    limits = (0.95, 1.05)
    cfg = napkin(rows, k_stretch=1e4, strain_limits=limits, effects=("attachments",), attachments={"nodes": corners(rows)})
    cfg["effects"].remove("gravity")  # the end effectors are the only load: a uniform stretch is the equilibrium
    sim = Simulator.from_config(cfg)
    rng = np.random.default_rng(5)
    rest = sim.attachment_targets.copy()
    centre = rest.mean(axis=0)
    stretched = centre + limits[1] * (rest - centre)

    def unit(k: int) -> np.ndarray:
        d = rng.normal(size=(k, 3))
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    path = [centre + (1 + 0.025 * k) * (rest - centre) for k in (1, 2)] + [stretched] * hold
    pulled = len(path)
    offset = np.zeros(3)
    for _ in range(20):  # rigid jumps of 0.5 m
        offset = offset + 0.5 * unit(1)[0]
        path.append(stretched + offset)
    jitter = np.zeros((4, 3))
    for _ in range(10):  # every corner jumps 0.5 m on its own
        jitter = jitter + 0.5 * unit(4)
        path.append(stretched + offset + jitter)
    fast_end = len(path)
    path += [stretched + offset] * hold
    mon = Monitor(energy=False)
    sim.set_solver(preset="gradient")  # recorded for backward: converged as the adjoint needs
    sim.set_recording(True)
    seen: dict[str, Any] = {"fast_max": -math.inf}

    def observe(k: int) -> None:
        if k == pulled - 1:
            seen["pulled"] = sim.principal_stretches()
        elif pulled <= k < fast_end:
            seen["fast_max"] = max(seen["fast_max"], float(sim.principal_stretches().max()))

    dl_dx = run(sim, mon, len(path), targets=lambda k: path[k], loss_grad=lambda s: np.zeros((s.num_nodes, 3)),
                after_step=observe)
    if dl_dx is not None:
        dl_dx[-1] = (sim.positions - sim.positions.mean(axis=0)) / sim.num_nodes  # loss: spread at the end
    backward(sim, mon, dl_dx)
    s = seen.get("pulled", np.array([math.nan]))
    tol = 1e-3
    corner_err = float(np.linalg.norm(sim.positions[sim.attachment_nodes] - path[-1], axis=1).max())
    final = sim.principal_stretches()
    return finish(mon, {
        "within_strain_limits": (limits[0] - tol <= s.min() and s.max() <= limits[1] + tol,
                                 f"stretches after the pull [{s.min():.6f}, {s.max():.6f}] within [{limits[0]}, {limits[1]}] +- {tol:g}"),
        "at_strain_limit": (s.min() >= limits[1] - tol, f"min stretch after the pull {s.min():.6f} >= {limits[1] - tol:g}"),
        "corners_follow": (corner_err <= 0.01, f"corner-to-target distance after the jumps {corner_err:.2e} m (bound 0.01)"),
    }, None, stretch_bounds=(limits[0] - tol, limits[1] + tol), fast_max_stretch=seen["fast_max"],
        final_stretch_range=[float(final.min()), float(final.max())])


def case_sphere_friction(size: str, workdir: Path, mu: float) -> dict:
    """``sphere.toml`` (h = 1/180 s) with friction mu = 0 or 2, forward and backward (loss: mean
    height on every step). Every impulse must lie in the Coulomb cone (mu = 0: purely normal),
    nodes sticking to the sphere must not move tangentially (< 1e-4 m/s); mu = 0 never sticks to
    the sphere, mu = 2 holds the draped cloth: >= 90 % of the active sphere contacts stick over
    the last fifth of the run. (Self-contacts keep the scene's mu 0.1.)"""
    rows = pick(size, 15, 25)
    steps = pick(size, 540, 1080)
    sim = Simulator.from_config(sphere_config(mu, rows))
    sim.set_solver(preset="gradient")  # recorded for backward: converged as the adjoint needs
    sim.set_recording(True)
    mon = Monitor(energy=True)
    laws: list[dict] = []
    state = {"x": sim.positions}

    def check(_: int) -> None:
        laws.append(contact_law(sim, state["x"]))
        state["x"] = sim.positions

    n = sim.num_nodes
    dl_dx = run(sim, mon, steps, loss_grad=lambda s: np.tile([0.0, 1.0 / (n * steps), 0.0], (n, 1)), after_step=check)
    backward(sim, mon, dl_dx)
    cone = max((w["cone"] for w in laws), default=-math.inf)
    speed = max((w["stick_speed"] for w in laws), default=0.0)
    tail = laws[-max(len(laws) // 5, 1):]
    stick, active = sum(w["stick"] for w in tail), sum(w["active"] for w in tail)
    fraction = stick / active if active else 0.0
    checks = {
        "friction_cone": (cone <= 1e-9, f"max (|J_T| - mu J_n) / max J_n = {cone:.2e} (bound 1e-9)"),
        "sticking_nodes_rest": (speed <= 1e-4, f"max tangential speed of sticking nodes {speed:.1e} m/s (bound 1e-4)"),
        "lands": (mon.obstacle_contacts > 0, f"{mon.obstacle_contacts} active obstacle contacts"),
    }
    if mu == 0:
        total = sum(w["stick"] for w in laws)
        checks["never_sticks"] = (total == 0, f"{total} contacts sticking to the sphere (frictionless: 0)")
    else:
        checks["holds_draped_cloth"] = (fraction >= 0.9, f"{fraction:.0%} of active sphere contacts stick over the last fifth (bound 90 %)")
    return finish(mon, checks, ENERGY_BOUND, mu=mu, stick_fraction_tail=fraction)


def case_slope_stick_slip(size: str, workdir: Path) -> dict:
    """``slope.toml`` swept across the stick/slip boundary mu = tan 42 deg = 0.900: mu = 0 and 2
    and 0.5, 0.9, 0.98, 1.02, 1.1 x tan. Released at rest, the ribbon slides rigidly when
    mu < tan (downhill travel = the implicit-Euler closed form, relative error <= 1e-6) and
    sticks when mu > tan (travel <= 1e-9 m). Backward (krylov) through each rollout for the
    loss = mean downhill travel at the end: its mu gradient must equal the closed form's,
    ``-g cos h^2 N (N + 1) / 2``, when sliding and vanish (<= 1e-9) when sticking."""
    rows = pick(size, 12, 24)
    steps = pick(size, 60, 300)
    tan = math.tan(math.radians(SLOPE_DEG))
    mus = [0.0, 0.5 * tan, 0.9 * tan, 0.98 * tan, 1.02 * tan, 1.1 * tan, 2.0]
    mon = Monitor(energy=True)
    checks: dict[str, tuple[bool, str]] = {}
    sweep = []
    for mu in mus:
        sim = Simulator.from_config(slope_config(mu, rows))
        sim.set_solver(preset="gradient")  # recorded for backward: converged as the adjoint needs
        sim.set_recording(True)
        x0 = sim.positions
        n = sim.num_nodes
        dl_dx = run(sim, mon, steps, loss_grad=lambda s: np.zeros((s.num_nodes, 3)))
        travel = float(np.mean((sim.positions - x0) @ downhill()))
        expected = sliding_distance(mu, 0.01, steps)
        grad_expected = -GRAVITY * math.cos(math.radians(SLOPE_DEG)) * 0.01 ** 2 * steps * (steps + 1) / 2 if mu < tan else 0.0
        grad = math.nan
        if dl_dx is not None:
            dl_dx[-1] = np.tile(downhill() / n, (n, 1))
            grad = float(backward(sim, mon, dl_dx)["mu_obstacles"][0])
        name = f"mu_{mu / tan:.2f}tan"
        if mu < tan:
            err = abs(travel - expected) / expected
            checks[f"{name}_slides"] = (err <= 1e-6, f"mu {mu:.3f}: travel {travel:.6g} m vs closed form {expected:.6g} (rel. error {err:.1e}, bound 1e-6)")
            gerr = abs(grad - grad_expected) / abs(grad_expected)
            checks[f"{name}_grad"] = (gerr <= 1e-6, f"dL/dmu {grad:.6g} vs {grad_expected:.6g} (rel. error {gerr:.1e}, bound 1e-6)")
        else:
            checks[f"{name}_sticks"] = (abs(travel) <= 1e-9, f"mu {mu:.3f}: travel {travel:.1e} m (bound 1e-9)")
            checks[f"{name}_grad"] = (abs(grad) <= 1e-9, f"dL/dmu {grad:.1e} (sticking: 0, bound 1e-9)")
        sweep.append({"mu": mu, "travel_m": travel, "expected_m": expected, "dl_dmu": grad, "expected_dl_dmu": grad_expected})
    return finish(mon, checks, ENERGY_BOUND, sweep=sweep)


def _crumple(size: str, shape: str, rows: int, width: float, radius: float, drop: float,
             turn_deg: float, steps: int) -> dict:
    """Shared body of the crumpling cases: forward with recording, a loss on every step (mean
    squared distance to the obstacle's lowest point), Krylov backward through all the contacts.
    Contacts of both kinds must occur."""
    sim = Simulator.from_config(crumple_config(shape, rows, width, radius, drop, turn_deg))
    sim.set_solver(preset="gradient")  # recorded for backward: converged as the adjoint needs
    sim.set_recording(True)
    bottom = np.array([0.0, 0.0, 0.0])
    mon = Monitor(energy=True)
    dl_dx = run(sim, mon, steps, loss_grad=lambda s: 2 * (s.positions - bottom) / (s.num_nodes * steps))
    backward(sim, mon, dl_dx)
    return finish(mon, {
        "obstacle_contacts_occur": (mon.obstacle_contacts > 0, f"{mon.obstacle_contacts} active obstacle contacts (summed over steps)"),
        "self_contacts_occur": (mon.self_contacts > 0, f"{mon.self_contacts} active self-contacts, at most {mon.max_self_contacts} at once"),
    }, ENERGY_BOUND, shape=shape)


def case_bowl_crumple(size: str, workdir: Path) -> dict:
    """A 1.6 m napkin turned 30 degrees falls into ``bowl.toml``'s bowl (radius 1, rim at 0.7)
    with self-collision on, and crumples against the spherical wall: forward and backward."""
    return _crumple(size, "bowl", rows=pick(size, 25, 51), width=1.6, radius=pick(size, 0.05, 0.03),
                    drop=1.15, turn_deg=30.0, steps=pick(size, 250, 500))


def case_pyramid_crumple(size: str, workdir: Path) -> dict:
    """A 1.2 m napkin (more cloth than the 1 m pit opening) turned 30 degrees falls into
    ``pyramid.toml``'s upside-down pyramid and folds against its four walls, with many
    simultaneous obstacle and self-contacts (self radius raised to 0.06 / 0.04 m so that the
    folds touch): forward and backward."""
    return _crumple(size, "pyramid", rows=pick(size, 20, 30), width=1.2, radius=pick(size, 0.06, 0.04),
                    drop=1.3, turn_deg=30.0, steps=pick(size, 200, 400))


def case_obj_degenerate(size: str, workdir: Path) -> dict:
    """Imported OBJ meshes with zero-area triangles are rejected at load with a
    :class:`~diffcloth_gym.errors.MeshError` (a ``ValueError``) that names the problem and the
    triangle: three collinear vertices, two distinct vertices at the same point, a face repeating
    a vertex, and a sliver of aspect ratio 1e-10 (area below the loader's 1e-12 x squared
    bounding-box diagonal). After every rejection a simulator built before keeps stepping, and
    a valid OBJ still loads and runs."""
    good = write_grid_obj(workdir / "good.obj", 5, 1.0)
    cfg = {"h": 0.01, "effects": ["gravity", "stretch", "bend"], "mesh": {"kind": "obj", "path": str(good)},
           "material": {"density": 0.2, "k_stretch": 200.0, "k_bend": 0.01}}
    before = Simulator.from_config(cfg)
    mon = Monitor(energy=True)
    mon.start(before)
    bad_meshes = {
        "collinear": ("v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 0 1\nf 1 4 2\nf 1 2 3\n", ["degenerate", "triangle 1"]),
        "coincident_vertices": ("v 0 0 0\nv 1 0 0\nv 1 0 0\nv 0 0 1\nf 1 2 4\nf 1 2 3\n", ["degenerate", "triangle 1"]),
        "repeated_vertex": ("v 0 0 0\nv 1 0 0\nv 0 0 1\nf 1 2 3\nf 1 2 2\n", ["repeats a vertex", "triangle 1"]),
        "sliver_1e-10": (None, ["degenerate"]),
    }
    checks: dict[str, tuple[bool, str]] = {}
    for name, (text, needles) in bad_meshes.items():
        path = workdir / f"{name}.obj"
        if text is None:
            write_grid_obj(path, 10, 1.0, sliver=1e-10)
        else:
            path.write_text(text)
        try:
            Simulator.from_config({**cfg, "mesh": {"kind": "obj", "path": str(path)}})
            checks[f"{name}_rejected"] = (False, "loaded without error")
        except MeshError as e:
            msg = str(e)
            ok = isinstance(e, ValueError) and all(s in msg for s in needles) and str(path) in msg
            checks[f"{name}_rejected"] = (ok, f"MeshError: {msg}")
        before.step()  # the simulator built before the rejected load stays usable
        mon.observe()
    after = Simulator.from_config(cfg)
    run(after, mon, 20)
    checks["usable_after_rejections"] = (mon.steps == 24 and mon.nan_count == 0,
                                         f"{mon.steps} steps after 4 rejected loads, all finite")
    return finish(mon, checks, ENERGY_BOUND)


def case_obj_sliver(size: str, workdir: Path, aspect: float, expect: str) -> dict:
    """An imported OBJ napkin (10 x 10 grid, 1 m) with a strip of 18 slivers of the given aspect
    ratio (width / height), pinned at a corner, to fall onto a sphere (radius 0.5, mu 0.3) with
    self-collision, forward and backward. What the simulator does (``expect``): the loader
    rejects triangles with ``2 area / longest edge^2 < 1e-6`` (their cotangent bending weights,
    ~1/aspect, made free fall gain energy 1e3-fold in 20 steps at 1e-8), so aspect 1e-4 and 1e-5
    are simulated and 1e-6 (ratio 1e-6 / (1 + 1e-12)) and 1e-8 are rejected. Simulated: stable
    (finite, no energy growth, no penetration) with finite gradients. Rejected: a ``MeshError``
    (a ``ValueError``) naming the file, the triangle and the sliver, and a simulator built before
    keeps stepping."""
    path = write_grid_obj(workdir / f"sliver_{aspect:g}.obj", 10, 1.0, sliver=aspect)
    cfg = napkin(10, strain_limits=(0.95, 1.05), effects=("attachments", "obstacle_contact", "friction", "self_collision"),
                 mesh={"kind": "obj", "path": str(path)}, placement={"translate": [0.0, 1.0, 0.0]},
                 attachments={"nodes": [0]}, contact={"thickness": 0.01},
                 obstacles=[{"mu": 0.3, "shape": {"kind": "sphere", "center": [0.0, 0.0, 0.0], "radius": 0.5}}],
                 self_collision={"radius": 0.02})
    mon = Monitor(energy=True)
    try:
        sim = Simulator.from_config(cfg)
    except MeshError as e:
        before = Simulator.from_config({**cfg, "mesh": {"kind": "obj", "path": str(write_grid_obj(workdir / "plain.obj", 10, 1.0))}})
        run(before, mon, 10)  # a simulator built before the rejected load keeps working
        msg = str(e)
        return finish(mon, {
            "documented_outcome": (expect == "rejected", f"rejected at load, documented: {expect}"),
            "clear_error": (isinstance(e, ValueError) and str(path) in msg and "triangle" in msg and "sliver" in msg,
                            f"MeshError: {msg}"),
            "usable_after_rejection": (mon.steps == 10, f"{mon.steps} steps of another simulator after the rejection"),
        }, ENERGY_BOUND, aspect=aspect, outcome="rejected")
    tri, x = sim.triangles, sim.rest_positions
    e = [np.linalg.norm(x[tri[:, i]] - x[tri[:, (i + 1) % 3]], axis=1) for i in range(3)]
    area = 0.5 * np.linalg.norm(np.cross(x[tri[:, 1]] - x[tri[:, 0]], x[tri[:, 2]] - x[tri[:, 0]]), axis=1)
    worst_aspect = float(np.min(2 * area / np.max(e, axis=0) ** 2))  # height / longest edge
    steps = pick(size, 100, 300)
    sim.set_solver(preset="gradient")  # recorded for backward: converged as the adjoint needs
    sim.set_recording(True)
    dl_dx = run(sim, mon, steps, loss_grad=lambda s: 2 * s.positions / (s.num_nodes * steps))
    backward(sim, mon, dl_dx)
    return finish(mon, {
        "documented_outcome": (expect == "simulated", f"accepted and simulated, documented: {expect}"),
        "mesh_has_slivers": (worst_aspect <= 1.01 * aspect, f"worst triangle height / longest edge {worst_aspect:.1e}"),
        "lands": (mon.obstacle_contacts > 0, f"{mon.obstacle_contacts} active obstacle contacts"),
    }, ENERGY_BOUND, aspect=aspect, outcome="simulated")


def case_sticking_contact_loop(size: str, workdir: Path) -> dict:
    """The smallest closed loop of sticking contacts: two separate triangles lie on a rough floor
    (mu 0.5) with their tips 2 mm apart (self radius 2 mm) and slide into each other at 1 m/s
    while pressed down. Both tips stick to the floor and to each other, which the forward
    Gauss-Seidel contact solve handles; the backward must too. Checks the Coulomb law and that
    the tips are at rest (stuck) after the 5 steps (both sizes)."""
    path = workdir / "two_triangles.obj"
    path.write_text("v 0 0.01 0\nv -1 0.01 0.5\nv -1 0.01 -0.5\n"
                    "v 0.002 0.01 0\nv 1 0.01 -0.5\nv 1 0.01 0.5\nf 1 2 3\nf 4 5 6\n")
    sim = Simulator.from_config({
        "h": 0.01, "effects": ["gravity", "stretch", "obstacle_contact", "friction", "self_collision"],
        "mesh": {"kind": "obj", "path": str(path)}, "material": {"density": 0.2, "k_stretch": 100.0},
        "contact": {"thickness": 0.01, "margin": 0.01},
        "obstacles": [{"mu": 0.5, "shape": {"kind": "plane", "point": [0, 0, 0], "normal": [0, 1, 0]}}],
        "self_collision": {"radius": 0.002, "mu": 1.0}})
    v = np.zeros((6, 3))
    v[:3, 0], v[3:, 0], v[:, 1] = 1.0, -1.0, -0.1
    sim.reset(v=v)
    sim.set_solver(preset="gradient")  # recorded for backward: converged as the adjoint needs
    sim.set_recording(True)
    mon = Monitor(energy=True)
    laws: list[dict] = []
    x_before = [sim.positions]
    steps = 5  # a reproducer: the same at both sizes (later the sliding far ends push the tips)
    dl_dx = run(sim, mon, steps, loss_grad=lambda s: np.ones((6, 3)) / 6,
                after_step=lambda k: laws.append(contact_law(sim, x_before[-1])) or x_before.append(sim.positions))
    backward(sim, mon, dl_dx)
    cone = max((w["cone"] for w in laws), default=-math.inf)
    tips = float(np.abs(sim.velocities[[0, 3], 0]).max())
    return finish(mon, {
        "friction_cone": (cone <= 1e-9, f"max (|J_T| - mu J_n) / max J_n = {cone:.2e} (bound 1e-9)"),
        "tips_stuck": (tips <= 1e-9, f"tip speeds along x {tips:.1e} m/s at the end (bound 1e-9)"),
        "loop_forms": (mon.self_contacts > 0, f"{mon.self_contacts} active self-contacts"),
    }, ENERGY_BOUND)
