"""Accuracy vs time: what each accuracy knob of the simulator costs (issue 5, item 1).

``python -m diffcloth_gym.bench accuracy [--part forward|backward|gradient|timestep|all]
[--scene wind,slope,hat,hat_contact,sock] [--res 12 24 48] [--quick] [--out DIR]``

Parts (each a few small functions below; every row in the JSON has a ``part`` field):

1. ``forward``: PD tolerance and iteration-cap sweeps, plain PD vs Anderson; ms/step,
   iterations/step and trajectory error against a tightly converged run; a Pareto plot per scene.
2. ``backward``: the paper's Table 1 with our numbers: direct vs fixed_point vs krylov adjoint
   solves at eps 1e-2 ... 1e-9 on Wind and Slope; time, stage shares, fail %, speedup, gradient
   error against direct; the paper's numbers beside ours.
3. ``gradient``: the gradient error caused by the forward tolerance (with and without the
   recording polish) against the gradient of a converged trajectory (Hat, Sock, Wind 24x24).
4. ``timestep``: error and time against the time step h for a fixed simulated duration.

Writes ``accuracy_time.{json,md}`` and PNG plots (``accuracy_*.png``) to ``benchmarks/results``
(or ``--out``). A run of some parts keeps the other parts' rows from an earlier run in the same
folder (their own meta is kept in ``meta.parts``). All runs are single-threaded
(``parallel=False``) and time is measured inside Rust (the simulator's profile) where possible.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence, TypeVar

import numpy as np

from diffcloth_gym import Simulator
from diffcloth_gym.bench import results
from diffcloth_gym.bench.scene_utils import compare, contact_free, load_scene, trajectory_error

T = TypeVar("T")

NAME = "accuracy_time"
PARTS = ("forward", "backward", "gradient", "timestep")
SCENE_NAMES = ("wind", "slope", "hat", "hat_contact", "sock")

# -- settings of the study ------------------------------------------------------------------
#: Forward sweep: PD tolerances (RMS per-coordinate PD update in metres) and iteration caps.
FORWARD_TOLERANCES = (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10)
FORWARD_CAPS = (10, 20, 50, 100, 150, 300)
#: Cap for the tolerance sweep: generous so that plain PD reaches even 1e-10 (counted if not).
SWEEP_MAX_ITERATIONS = 5000
#: The reference trajectory: Anderson converged far below every swept tolerance.
REFERENCE_SOLVER = dict(acceleration="anderson", tolerance=1e-12, max_iterations=20000)
#: A run converged 10x tighter than the reference: its error against the reference is the floor
#: below which trajectory errors are not resolved (large where the scene amplifies per-step
#: residuals, e.g. the wrinkling 48x48 cloth). Capped: 1e-13 is near round-off.
REFERENCE_CHECK_SOLVER = dict(acceleration="anderson", tolerance=1e-13, max_iterations=2000)
#: Adjoint tolerances of the backward sweep (the paper varied 1e-1 ... 1e-9).
BACKWARD_EPS = (1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9)
#: Iteration cap of the iterative adjoint solvers (the API default).
BACKWARD_MAX_ITERATIONS = 500
#: Gradient part: the converged trajectory the gradients are compared with (as
#: tests/test_gradient_consistency.py).
GRADIENT_REFERENCE = dict(acceleration="anderson", tolerance=1e-12, max_iterations=5000,
                          record_tolerance=1e-12, record_max_iterations=5000)
#: Per-step effector motion of the gradient part (as tests/test_gradient_consistency.py).
GRADIENT_DRIVE_PER_STEP = np.array([0.0, -0.003, 0.002])
#: Effector velocity (m/s) of the garments in the forward and time-step parts: the same motion
#: as the gradient part at the Hat's h = 0.01 s, so that the hat swings instead of settling.
GARMENT_DRIVE = (0.0, -0.3, 0.2)
#: Time-step part: simulated duration, time steps, reference time step, solver tolerances.
TIMESTEP_DURATION = 1.0
TIMESTEP_HS = (1 / 25, 1 / 50, 1 / 100, 1 / 200, 1 / 400)
TIMESTEP_REFERENCE_H = 1 / 1600
TIMESTEP_TOLERANCES = (1e-8, 1e-10)
TIMESTEP_REFERENCE_SOLVER = dict(acceleration="anderson", tolerance=1e-11, max_iterations=5000)

#: The reference C++ code's Hat gradient (w.r.t. v0, 400 steps, exact LU backward, no clipping)
#: relative to a 1e-11-converged trajectory's, per forward tolerance (DESIGN.md section 3).
CPP_HAT_GRADIENT_ERROR = {1e-8: 1.7e10, 1e-6: 3e83, 1e-4: 6e129}

#: Paper Table 1 (DiffCloth, Li et al. 2022). Per row: test, res, solver, eps, backprop time
#: for the whole rollout in s, shares in % (dP, dR, Iter., Direct, Other; None = "-"), fail %,
#: speedup. Re-aligned from a garbled transcription: the "-" cells were partly dropped; each
#: row's shares were placed so that they sum to 100 % and every speedup matches
#: direct time / time (except Slope 24x24 1e-6, see TABLE1_CAVEATS).
PAPER_TABLE1: list[tuple] = [
    ("wind", 12, "direct", None, 0.606, 13.9, None, None, 84.4, 1.7, None, None),
    ("wind", 12, "fixed_point", 1e-4, 0.212, 39.9, 0.0, 55.5, None, 4.6, 0.0, 2.9),
    ("wind", 12, "fixed_point", 1e-6, 0.424, 19.2, None, 78.5, None, 2.3, None, 1.4),
    ("wind", 24, "direct", None, 3.360, 9.9, None, None, 89.1, 1.0, None, None),
    ("wind", 24, "fixed_point", 1e-4, 0.591, 58.2, 0.0, 36.3, None, 5.5, 0.0, 5.7),
    ("wind", 24, "fixed_point", 1e-6, 2.858, 11.7, None, 87.2, None, 1.1, None, 1.2),
    ("wind", 48, "direct", None, 24.001, 6.8, None, None, 92.5, 0.7, None, None),
    ("wind", 48, "fixed_point", 1e-4, 2.262, 63.2, 0.0, 29.7, None, 7.1, 0.0, 10.6),
    ("wind", 48, "fixed_point", 1e-6, 29.255, 5.4, None, 82.6, 11.5, 0.6, 15.0, 0.8),
    ("slope", 12, "direct", None, 0.978, 13.0, 3.4, None, 82.4, 1.2, None, None),
    ("slope", 12, "fixed_point", 1e-4, 0.312, 70.1, 9.4, 16.1, None, 4.5, 0.0, 3.1),
    ("slope", 12, "fixed_point", 1e-6, 0.643, 18.9, 2.7, 76.8, None, 1.6, None, 1.5),
    ("slope", 24, "direct", None, 5.331, 10.4, 1.5, None, 87.4, 0.7, None, None),
    ("slope", 24, "fixed_point", 1e-4, 0.781, 70.1, 9.4, 16.1, None, 4.5, 0.0, 6.8),
    ("slope", 24, "fixed_point", 1e-6, 1.507, 34.7, 4.9, 58.1, None, 2.4, None, 3.7),
    ("slope", 48, "direct", None, 37.296, 6.5, 0.7, None, 92.5, 0.4, None, None),
    ("slope", 48, "fixed_point", 1e-4, 3.095, 68.1, 8.2, 19.8, None, 3.8, 0.0, 12.0),
    ("slope", 48, "fixed_point", 1e-6, 6.825, 31.2, 3.5, 63.6, None, 1.8, None, 5.5),
]
#: Rollout lengths of the paper's tests (Fig. 6): Table 1 times are totals over these.
PAPER_STEPS = {"wind": 200, "slope": 300}
TABLE1_CAVEATS = (
    "Paper Table 1 caveats: its \"Ours\" is the fixed-point (Jacobi) iteration of Eqn. 30, so it "
    "sits beside our `fixed_point` rows (our `krylov` has no paper counterpart); times are totals "
    "over 200 (Wind) / 300 (Slope) steps, shown here per step; \"-\" cells (printed as blank) are "
    "read as not applicable / zero. In the transcription Slope 24x24 (1e-4) repeats Slope 12x12 "
    "(1e-4)'s shares exactly, and Slope 24x24 (1e-6) prints speedup 3.7x where 5.331 s / 1.507 s "
    "= 3.5x; both are reproduced as printed."
)


# -- scenes ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class Scene:
    """A scene of the study: a config plus how long and how it is driven."""

    label: str
    config: dict
    steps: int
    #: Effector (attachment target) velocity in m/s, or None to keep the targets fixed.
    drive: tuple[float, float, float] | None = None
    #: Standard deviation of the seeded random initial velocities (0: start at rest).
    v_sigma: float = 0.0
    extra: dict = field(default_factory=dict)


def grid_scene(name: str, res: int, steps: int, v_sigma: float = 0.0) -> Scene:
    """Wind or Slope at ``res x res`` nodes."""
    return Scene(f"{name}{res}x{res}", load_scene(name, res), steps, None, v_sigma)


def garment_scene(name: str, steps: int, contact: bool = False, drive: Any = GARMENT_DRIVE) -> Scene:
    """Hat or Sock, contact-free (as in the gradient consistency test) unless ``contact``."""
    cfg = load_scene(name)
    label = name if contact else f"{name}_nocontact"
    return Scene(label, cfg if contact else contact_free(cfg), steps, drive)


def default_record_tolerance() -> float:
    """The simulator's default ``solver.record_tolerance`` (the polish of recorded steps)."""
    return Simulator.from_config("napkin").solver()["record_tolerance"]


def make_sim(cfg: dict, **solver: Any) -> Simulator:
    """A single-threaded simulator (the study compares algorithms, not thread counts)."""
    sim = Simulator.from_config(cfg)
    sim.set_solver(parallel=False, **solver)
    return sim


def initial_velocities(sim: Simulator, sigma: float, seed: int = 0) -> np.ndarray | None:
    """Seeded random initial velocities (None for rest): identical for every run of a scene."""
    if sigma == 0.0:
        return None
    return np.random.default_rng(seed).normal(0.0, sigma, (sim.num_nodes, 3))


#: Timing guard counters (reported in the meta block): reruns because another process took
#: the core, and measurements still disturbed after the last rerun.
TIMING = {"reruns": 0, "disturbed": 0}
#: A run counts as disturbed when its time inside Rust exceeds the thread's CPU time by this
#: factor (plus 2 ms): the single-threaded simulator then waited for a core.
DISTURBED_RATIO = 1.25
RERUNS = 2


def undisturbed(run: Callable[[], T], rust_seconds: Callable[[T], float]) -> T:
    """Runs ``run`` (deterministic) and reruns it up to RERUNS times while it was disturbed;
    returns the run with the least time inside Rust.

    The machine is shared: when other jobs occupy both cores, the Rust wall-clock profile of a
    single-threaded run inflates (seen: 10x on one Hat setting) while its thread CPU time does
    not, so the two are compared to detect it.
    """
    best, best_s = None, math.inf
    for attempt in range(1 + RERUNS):
        cpu = time.thread_time()
        out = run()
        rust_s, cpu_s = rust_seconds(out), time.thread_time() - cpu
        if rust_s < best_s:
            best, best_s = out, rust_s
        if rust_s <= DISTURBED_RATIO * cpu_s + 2e-3:
            return best
        if attempt < RERUNS:
            TIMING["reruns"] += 1
    TIMING["disturbed"] += 1
    return best


def rollout(sim: Simulator, scene: Scene, steps: int, h: float | None = None) -> tuple[np.ndarray, dict, int]:
    """Runs ``steps`` steps from the scene's initial state with the current solver settings.

    Returns the trajectory (steps + 1, n, 3), the Rust profile of just these steps, and the
    number of steps that stopped unconverged. Effector targets move with ``scene.drive``,
    evaluated at the end of each step (implicit Euler), so that runs at different h see the
    same motion in time. Rerun if another process disturbed the timing (see undisturbed).
    """
    return undisturbed(lambda: _rollout_once(sim, scene, steps, h), lambda out: out[1]["total_s"])


def _rollout_once(sim: Simulator, scene: Scene, steps: int, h: float | None) -> tuple[np.ndarray, dict, int]:
    h = sim.params()["h"] if h is None else h
    sim.reset(v=initial_velocities(sim, scene.v_sigma))
    t0 = sim.attachment_targets
    traj = np.empty((steps + 1, sim.num_nodes, 3))
    traj[0] = sim.positions
    unconverged = 0
    sim.reset_profile()
    for k in range(steps):
        targets = None if scene.drive is None else t0 + np.asarray(scene.drive) * (k + 1) * h
        unconverged += not sim.step(attachment_targets=targets)["converged"]
        traj[k + 1] = sim.positions
    return traj, sim.profile(), unconverged


# -- part 1: forward ------------------------------------------------------------------------
def forward_settings(tolerances: Sequence[float], caps: Sequence[int]) -> list[tuple[str, dict]]:
    """The swept solver settings: (sweep kind, set_solver kwargs), plain and Anderson."""
    out = []
    for accel in ("none", "anderson"):
        out += [("tolerance", dict(acceleration=accel, tolerance=t, max_iterations=SWEEP_MAX_ITERATIONS)) for t in tolerances]
        # Tolerance 0: every step runs exactly `cap` iterations (the reference C++'s regime).
        out += [("cap", dict(acceleration=accel, tolerance=0.0, max_iterations=c)) for c in caps]
    return out


def forward_row(scene: Scene, sweep: str, solver: dict, prof: dict, unconverged: int, steps: int, err: float, nodes: int) -> dict:
    return {
        "part": "forward",
        "scene": scene.label,
        "nodes": nodes,
        "steps": steps,
        "acceleration": solver["acceleration"],
        "sweep": sweep,
        "tolerance": solver["tolerance"],
        "max_iterations": solver["max_iterations"],
        "ms_per_step": 1e3 * prof["total_s"] / steps,
        "iters_per_step": prof["iterations"] / steps,
        "unconverged_pct": 100.0 * unconverged / steps,
        "traj_rel_err": err,
    }


def mark_pareto(rows: list[dict], x: str = "ms_per_step", y: str = "traj_rel_err") -> None:
    """Sets ``pareto`` on each row: True if no other row is both faster and more accurate."""
    order = sorted(range(len(rows)), key=lambda i: (rows[i][x], rows[i][y]))
    best = math.inf
    for i in order:
        rows[i]["pareto"] = rows[i][y] < best
        best = min(best, rows[i][y])


def forward_scene(scene: Scene, tolerances: Sequence[float] = FORWARD_TOLERANCES, caps: Sequence[int] = FORWARD_CAPS) -> list[dict]:
    """All forward rows of one scene: the reference run plus the sweep, Pareto-marked."""
    sim = make_sim(scene.config, **REFERENCE_SOLVER)
    ref, ref_prof, ref_unconv = rollout(sim, scene, scene.steps)
    rows = []
    for sweep, solver in forward_settings(tolerances, caps):
        sim.set_solver(**solver)
        traj, prof, unconv = rollout(sim, scene, scene.steps)
        rows.append(forward_row(scene, sweep, solver, prof, unconv, scene.steps, trajectory_error(traj, ref), sim.num_nodes))
    mark_pareto(rows)
    reference = forward_row(scene, "reference", REFERENCE_SOLVER, ref_prof, ref_unconv, scene.steps, 0.0, sim.num_nodes)
    sim.set_solver(**REFERENCE_CHECK_SOLVER)
    traj, prof, unconv = rollout(sim, scene, scene.steps)
    check = forward_row(scene, "reference_check", REFERENCE_CHECK_SOLVER, prof, unconv, scene.steps, trajectory_error(traj, ref), sim.num_nodes)
    reference["pareto"] = check["pareto"] = False
    return [reference, check] + rows


def setting_label(row: dict) -> str:
    """Short name of a forward setting: ``plain 1e-08``, ``AA cap 50``."""
    accel = "AA" if row["acceleration"] == "anderson" else "plain"
    if row["sweep"] == "cap":
        return f"{accel} cap {row['max_iterations']}"
    return f"{accel} {row['tolerance']:.0e}"


def plot_forward(rows: list[dict], out_dir: Path) -> list[str]:
    """One log-log Pareto plot (ms/step vs trajectory error) per scene; returns file names."""
    plt = _pyplot()
    files = []
    for scene in dict.fromkeys(r["scene"] for r in rows):
        rs = [r for r in rows if r["scene"] == scene and r["sweep"] in ("tolerance", "cap") and r["traj_rel_err"] > 0]
        fig, ax = plt.subplots(figsize=(6.4, 4.8))
        for accel, color in (("none", "tab:blue"), ("anderson", "tab:orange")):
            for sweep, marker in (("tolerance", "o"), ("cap", "s")):
                pts = sorted((r["ms_per_step"], r["traj_rel_err"]) for r in rs if r["acceleration"] == accel and r["sweep"] == sweep)
                if pts:
                    name = ("plain PD" if accel == "none" else "Anderson") + (" (tolerance)" if sweep == "tolerance" else " (iteration cap)")
                    ax.plot(*zip(*pts), marker=marker, ls=":", color=color, alpha=0.8, label=name, mfc="none" if sweep == "cap" else color)
        front = sorted((r["ms_per_step"], r["traj_rel_err"]) for r in rs if r.get("pareto"))
        if front:
            ax.step(*zip(*front), where="post", color="k", lw=1.5, alpha=0.6, label="Pareto front")
        floor = next((r["traj_rel_err"] for r in rows if r["scene"] == scene and r["sweep"] == "reference_check"), 0.0)
        if floor > 0:
            ax.axhline(floor, color="gray", ls="--", lw=1, label="reference floor (1e-13 vs 1e-12 run)")
        for r in rs:
            if r.get("pareto"):
                ax.annotate(setting_label(r), (r["ms_per_step"], r["traj_rel_err"]), fontsize=6, xytext=(3, 3), textcoords="offset points")
        ax.set(xscale="log", yscale="log", xlabel="forward time (ms/step, one thread)", ylabel="trajectory error (relative L2)",
               title=f"{scene}: {rs[0]['steps'] if rs else 0} steps")
        ax.grid(True, which="both", alpha=0.3)
        _no_minor_labels(ax)
        ax.legend(fontsize=7)
        name = f"accuracy_forward_{scene}.png"
        fig.tight_layout()
        fig.savefig(out_dir / name, dpi=110)
        plt.close(fig)
        files.append(name)
    return files


# -- part 2: backward (Table 1) -------------------------------------------------------------
def record_for_backward(scene: Scene) -> tuple[Simulator, np.ndarray]:
    """Records a rollout at the default forward settings (Anderson 1e-8, recorded steps polished
    to the default record_tolerance) from seeded random velocities, and a controller-style loss: seeded random linear
    weights on the positions of every step (as scripts/bench_backward.py)."""
    sim = make_sim(scene.config)
    sim.set_recording(True)
    sim.reset(v=initial_velocities(sim, scene.v_sigma or 0.1))
    for _ in range(scene.steps):
        sim.step()
    n = sim.num_nodes
    dl_dx = np.random.default_rng(1).normal(0.0, 1.0, (scene.steps, n, 3)) / n
    return sim, dl_dx


def timed_backward(sim: Simulator, dl_dx: np.ndarray, solver: str, eps: float) -> tuple[dict, float, float]:
    """``(gradients, seconds inside Rust (sum of the stage profile), wall seconds)``, rerun if
    disturbed by another process (the backward is deterministic)."""
    def once() -> tuple[dict, float, float]:
        t = time.perf_counter()
        g = sim.backward(dl_dx=dl_dx, solver=solver, tolerance=eps, max_iterations=BACKWARD_MAX_ITERATIONS)
        wall = time.perf_counter() - t
        return g, float(sum(g["profile"].values())), wall

    return undisturbed(once, lambda out: out[1])


def gradient_vectors(g: dict) -> dict[str, np.ndarray]:
    """The gradients compared: v0, x0, the effector targets of every step, and all three."""
    targets = np.concatenate([np.ravel(a) for a in g["attachment_targets"]] or [np.zeros(0)])
    out = {"v0": np.ravel(g["v0"]), "x0": np.ravel(g["x0"])}
    if targets.size:
        out["targets"] = targets
    out["all"] = np.concatenate(list(out.values()))
    return out


def backward_row(scene: Scene, solver: str, eps: float | None, g: dict, rust_s: float, wall: float, direct_s: float, ref: dict) -> dict:
    prof = g["profile"]
    total = max(sum(prof.values()), 1e-300)
    fell_back = np.asarray(g["fell_back"], dtype=bool)
    # A step that fell back reports the iterations of the failed attempt only if the attempt
    # finished (0 on divergence/cap), so the mean is taken over the steps that converged.
    converged_its = np.asarray(g["iterations"], dtype=float)[~fell_back]
    row = {
        "part": "backward",
        "scene": scene.label,
        "steps": scene.steps,
        "dof": 3 * len(g["v0"]),
        "solver": solver,
        "eps": eps,
        "ms_per_step": 1e3 * rust_s / scene.steps,
        "wall_ms_per_step": 1e3 * wall / scene.steps,
        "dp_pct": 100 * prof["dp_s"] / total,
        "dr_pct": 100 * prof["dr_s"] / total,
        "solve_pct": 100 * prof["solve_s"] / total,
        "other_pct": 100 * prof["other_s"] / total,
        "fail_pct": 100.0 * float(fell_back.mean()),
        "mean_iters": float(converged_its.mean()) if converged_its.size and solver != "direct" else None,
        "speedup_vs_direct": direct_s / rust_s,
    }
    got = gradient_vectors(g)
    for key, want in gradient_vectors(ref).items():
        row[f"{key}_rel_err"], row[f"{key}_cos"] = compare(got[key], want)
    return row


def backward_scene(scene: Scene, eps_list: Sequence[float] = BACKWARD_EPS) -> list[dict]:
    """Direct, then fixed_point and krylov at every eps, on one recorded rollout."""
    sim, dl_dx = record_for_backward(scene)
    ref, direct_s, direct_wall = timed_backward(sim, dl_dx, "direct", 1e-10)
    rows = [backward_row(scene, "direct", None, ref, direct_s, direct_wall, direct_s, ref)]
    for solver in ("fixed_point", "krylov"):
        for eps in eps_list:
            g, rust_s, wall = timed_backward(sim, dl_dx, solver, eps)
            rows.append(backward_row(scene, solver, eps, g, rust_s, wall, direct_s, ref))
    return rows


def paper_rows() -> list[dict]:
    """Paper Table 1 as dicts with per-step times."""
    keys = ("test", "res", "solver", "eps", "time_s", "dp_pct", "dr_pct", "iter_pct", "direct_pct", "other_pct", "fail_pct", "speedup")
    out = []
    for values in PAPER_TABLE1:
        r = dict(zip(keys, values))
        r["ms_per_step"] = 1e3 * r["time_s"] / PAPER_STEPS[r["test"]]
        out.append(r)
    return out


def table1_rows(rows: list[dict]) -> list[dict]:
    """Our Table 1 (direct; fixed_point and krylov at 1e-4 and 1e-6) with the paper's numbers
    for the same test, resolution and eps beside ours."""
    paper = {(p["test"], p["res"], p["solver"], p["eps"]): p for p in paper_rows()}
    out = []
    for r in rows:
        if r["part"] != "backward" or r["eps"] not in (None, 1e-4, 1e-6):
            continue
        test = r["scene"].rstrip("0123456789x")
        res = int(r["scene"][len(test):].split("x")[0])
        # Only direct and fixed_point have a paper counterpart (the paper has no Krylov solver).
        p = paper.get((test, res, r["solver"], r["eps"]))
        solve_paper = None if p is None else (p["iter_pct"] or 0.0) + (p["direct_pct"] or 0.0)
        out.append({
            "test": r["scene"], "solver": r["solver"], "eps": r["eps"],
            "ms/step": r["ms_per_step"], "paper ms/step": None if p is None else p["ms_per_step"],
            "speedup": r["speedup_vs_direct"], "paper speedup": None if p is None else p["speedup"],
            "fail %": r["fail_pct"], "paper fail %": None if p is None else p["fail_pct"],
            "dP/dR/solve/other %": f"{r['dp_pct']:.0f}/{r['dr_pct']:.0f}/{r['solve_pct']:.0f}/{r['other_pct']:.0f}",
            "paper dP/dR/solve/other %": "" if p is None else "/".join(
                f"{v:.0f}" for v in (p["dp_pct"], p["dr_pct"] or 0.0, solve_paper, p["other_pct"] or 0.0)),
            "mean iters": r["mean_iters"], "grad rel err (all)": r["all_rel_err"], "cos (all)": r["all_cos"],
        })
    return out


def plot_backward(rows: list[dict], out_dir: Path) -> list[str]:
    """Gradient error (all gradients, relative L2 vs direct) against backward ms/step: one
    panel per resolution, one file per test."""
    plt = _pyplot()
    files = []
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    for test in dict.fromkeys(s.rstrip("0123456789x") for s in scenes):
        mine = [s for s in scenes if s.rstrip("0123456789x") == test]
        fig, axes = plt.subplots(1, len(mine), figsize=(4.6 * len(mine), 4.2), squeeze=False)
        for ax, scene in zip(axes[0], mine):
            rs = [r for r in rows if r["scene"] == scene]
            ymin = min((r["all_rel_err"] for r in rs if r["all_rel_err"] > 0), default=1e-8) / 3
            for solver, color in (("fixed_point", "tab:green"), ("krylov", "tab:purple")):
                every = [(r["ms_per_step"], r["all_rel_err"], r["eps"], r["fail_pct"]) for r in rs if r["solver"] == solver]
                pts = [p for p in every if p[1] > 0]
                if pts:
                    ax.plot([p[0] for p in pts], [p[1] for p in pts], "o-", color=color, label=solver)
                for x, y, eps, fail in pts:
                    ax.annotate(f"{eps:.0e}" + (f" ({fail:.0f}% fail)" if fail else ""), (x, y), fontsize=6, xytext=(3, 2), textcoords="offset points")
                # Every step fell back to LU: the gradient IS the direct one (error 0, not
                # drawable on a log axis); mark the times they cost at the bottom of the panel.
                direct_like = [p for p in every if p[1] == 0]
                if direct_like:
                    ax.plot([p[0] for p in direct_like], [ymin] * len(direct_like), "x", color=color, ms=8)
                    eps = sorted(p[2] for p in direct_like)
                    ax.annotate(f"eps {eps[-1]:.0e}..{eps[0]:.0e}: all steps fell back (= direct)", (min(p[0] for p in direct_like), ymin),
                                fontsize=6, xytext=(-60, 6), textcoords="offset points")
            direct = next(r for r in rs if r["solver"] == "direct")
            ax.axvline(direct["ms_per_step"], color="k", ls="--", label="direct (reference)")
            ax.set(xscale="log", yscale="log", xlabel="backward ms/step (one thread)", ylabel="gradient error vs direct (relative L2)",
                   title=f"{scene}: {rs[0]['steps']} steps")
            ax.grid(True, which="both", alpha=0.3)
            _no_minor_labels(ax)
            ax.legend(fontsize=7)
        fig.tight_layout()
        name = f"accuracy_backward_{test}.png"
        fig.savefig(out_dir / name, dpi=110)
        plt.close(fig)
        files.append(name)
    return files


# -- part 3: gradient error caused by the forward tolerance ---------------------------------
def gradient_settings(full: bool) -> list[tuple[str, dict]]:
    """(label, set_solver kwargs) of the gradient part. Without polish the recorded steps stop
    where an unrecorded step would (record_tolerance = tolerance, same cap); with polish they
    converge to the default record_tolerance whatever the tolerance (so all polished rows share one trajectory: two
    tolerances are run to show it). Caps have no polished variant: tolerance 0 would make the
    recorded steps run to record_max_iterations."""
    def loose(accel: str, tol: float, cap: int) -> dict:
        return dict(acceleration=accel, tolerance=tol, max_iterations=cap, record_tolerance=tol, record_max_iterations=cap)

    tols = (1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10) if full else (1e-4, 1e-6, 1e-8, 1e-10)
    caps = (20, 50, 100) if full else (50,)
    out = [(f"AA {t:.0e}, no polish", loose("anderson", t, 300)) for t in tols]
    out += [(f"AA cap {c}, no polish", loose("anderson", 0.0, c)) for c in caps]
    if full:
        # Plain PD without polish: the reference C++ code's algorithm and regime.
        out += [(f"plain {t:.0e}, no polish", loose("none", t, 2000)) for t in (1e-6, 1e-8)]
    rt = default_record_tolerance()
    out += [(f"AA {t:.0e}, polish {rt:.0e}", dict(acceleration="anderson", tolerance=t, max_iterations=300,
                                                  record_tolerance=rt, record_max_iterations=2000)) for t in ((1e-4, 1e-8) if full else (1e-8,))]
    return out


def gradient_run(scene: Scene, solver: dict) -> dict:
    """Records the scene's rollout (seeded random v0, effectors driven as in
    tests/test_gradient_consistency.py), takes a smooth-L1 loss to a target shape on every
    step and returns the direct-backward gradients plus the forward cost while recording."""
    sim = make_sim(scene.config, **solver)
    sim.set_recording(True)

    def record() -> tuple[list[np.ndarray], dict, int]:
        # reset() clears the tape: a rerun records the same rollout afresh.
        sim.reset(v=np.random.default_rng(0).normal(0, 0.2, (sim.num_nodes, 3)))
        t0 = sim.attachment_targets
        xs, unconverged = [], 0
        sim.reset_profile()
        for k in range(scene.steps):
            unconverged += not sim.step(attachment_targets=t0 + GRADIENT_DRIVE_PER_STEP * k)["converged"]
            xs.append(sim.positions)
        return xs, sim.profile(), unconverged

    xs, prof, unconverged = undisturbed(record, lambda out: out[1]["total_s"])
    target = sim.rest_positions + np.array([0.0, -1.0, 0.0])
    d = np.array(xs) - target
    dl_dx = np.where(np.abs(d) < 1, d, np.sign(d)) / sim.num_nodes
    # Timed once (the LU backward is the expensive call): a secondary column, not rerun.
    g = sim.backward(dl_dx=dl_dx, solver="direct")
    targets = np.concatenate([a.ravel() for a in g["attachment_targets"]])
    return {"v0": g["v0"], "targets": targets, "warnings": g["warnings"], "prof": prof, "unconverged": unconverged,
            "bwd_s": float(sum(g["profile"].values())), "grad_norm": float(np.linalg.norm(g["v0"]))}


def gradient_scene(scene: Scene, full: bool = True) -> list[dict]:
    """The gradient at each forward setting against the converged trajectory's gradient."""
    ref = gradient_run(scene, GRADIENT_REFERENCE)
    rows = [gradient_row(scene, "reference 1e-12", GRADIENT_REFERENCE, ref, ref)]
    for label, solver in gradient_settings(full):
        rows.append(gradient_row(scene, label, solver, gradient_run(scene, solver), ref))
    return rows


def gradient_row(scene: Scene, label: str, solver: dict, run: dict, ref: dict) -> dict:
    prof, steps = run["prof"], scene.steps
    v_rel, v_cos = compare(run["v0"], ref["v0"])
    t_rel, t_cos = compare(run["targets"], ref["targets"])
    polish = solver["record_tolerance"] < solver["tolerance"]
    return {
        "part": "gradient",
        "scene": scene.label,
        "steps": steps,
        "setting": label,
        "acceleration": solver["acceleration"],
        "tolerance": solver["tolerance"],
        "max_iterations": solver["max_iterations"],
        "record_tolerance": solver["record_tolerance"],
        "polish": polish,
        "fwd_ms_per_step": 1e3 * prof["total_s"] / steps,
        "iters_per_step": prof["iterations"] / steps,
        "polish_iters_per_step": prof["polish_iterations"] / steps,
        "unconverged_pct": 100.0 * run["unconverged"] / steps,
        "v0_rel_err": v_rel,
        "v0_cos": v_cos,
        "targets_rel_err": t_rel,
        "targets_cos": t_cos,
        "v0_grad_norm": run["grad_norm"],
        "warned": bool(run["warnings"]),
        "warnings": run["warnings"],
        "bwd_ms_per_step": 1e3 * run["bwd_s"] / steps,
        "cpp_reference_rel_err": CPP_HAT_GRADIENT_ERROR.get(solver["tolerance"]) if scene.label.startswith("hat") and not polish and solver["acceleration"] == "none" else None,
    }


def cheapest_within(rows: list[dict], scene: str, limit: float = 1e-2) -> dict | None:
    """The non-reference setting with the lowest forward ms/step (while recording) whose v0 and
    target gradients are both within ``limit`` (relative L2) of the converged gradient."""
    ok = [r for r in rows if r["part"] == "gradient" and r["scene"] == scene and not r["setting"].startswith("reference")
          and r["v0_rel_err"] <= limit and r["targets_rel_err"] <= limit]
    return min(ok, key=lambda r: r["fwd_ms_per_step"]) if ok else None


# -- part 4: time step ----------------------------------------------------------------------
def sample_positions(scene: Scene, h: float, solver: dict, duration: float, every: float) -> tuple[np.ndarray, dict, int]:
    """Positions at t = every, 2 every, ..., duration (plus t = 0) for time step h; the profile
    and step count. ``every`` must be a multiple of h."""
    cfg = dict(scene.config, h=h)
    sim = make_sim(cfg, **solver)
    per_sample = round(every / h)
    samples = round(duration / every)
    assert abs(per_sample * h - every) < 1e-9 * every, (h, every)
    traj, prof, unconv = rollout(sim, scene, per_sample * samples, h)
    return traj[::per_sample], prof, per_sample * samples


def timestep_scene(scene: Scene, hs: Sequence[float] = TIMESTEP_HS, h_ref: float = TIMESTEP_REFERENCE_H,
                   duration: float = TIMESTEP_DURATION, tolerances: Sequence[float] = TIMESTEP_TOLERANCES) -> list[dict]:
    """Error (relative L2 of the positions at the common times k * max(hs)) and time against h."""
    every = max(hs)
    ref, _, _ = sample_positions(scene, h_ref, TIMESTEP_REFERENCE_SOLVER, duration, every)
    rows = []
    for tol in tolerances:
        for h in hs:
            solver = dict(acceleration="anderson", tolerance=tol, max_iterations=2000)
            traj, prof, steps = sample_positions(scene, h, solver, duration, every)
            rows.append({
                "part": "timestep",
                "scene": scene.label,
                "h": h,
                "one_over_h": round(1 / h),
                "tolerance": tol,
                "steps": steps,
                "ms_per_step": 1e3 * prof["total_s"] / steps,
                "ms_total": 1e3 * prof["total_s"],
                "iters_per_step": prof["iterations"] / steps,
                "rel_err": trajectory_error(traj, ref),
                "final_rel_err": float(np.linalg.norm(traj[-1] - ref[-1]) / max(np.linalg.norm(ref[-1] - ref[0]), 1e-300)),
            })
    return rows


def plot_timestep(rows: list[dict], out_dir: Path) -> list[str]:
    """Error vs h and error vs total time, one line per scene and tolerance."""
    plt = _pyplot()
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4.2))
    for scene in dict.fromkeys(r["scene"] for r in rows):
        for tol, ls in zip(sorted({r["tolerance"] for r in rows}), ("--", "-", ":")):
            rs = sorted((r for r in rows if r["scene"] == scene and r["tolerance"] == tol), key=lambda r: r["h"])
            label = f"{scene}, tol {tol:.0e}"
            a.plot([r["h"] for r in rs], [r["rel_err"] for r in rs], "o" + ls, label=label)
            b.plot([r["ms_total"] for r in rs], [r["rel_err"] for r in rs], "o" + ls, label=label)
    a.set(xscale="log", yscale="log", xlabel="time step h (s)", ylabel="error vs h_ref (relative L2, common times)")
    b.set(xscale="log", yscale="log", xlabel="forward time for the whole duration (ms, one thread)", ylabel="error")
    return _save(fig, (a, b), out_dir, "accuracy_timestep.png")


def _save(fig: Any, axes: Sequence[Any], out_dir: Path, name: str) -> list[str]:
    """Grid, major-only labels and a legend on each axis; writes ``name`` and closes the figure."""
    for ax in axes:
        ax.grid(True, which="both", alpha=0.3)
        _no_minor_labels(ax)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out_dir / name, dpi=110)
    _pyplot().close(fig)
    return [name]


def plot_gradient(rows: list[dict], out_dir: Path) -> list[str]:
    """v0-gradient error against forward ms/step (while recording), one line per scene."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.8))
    for scene in dict.fromkeys(r["scene"] for r in rows):
        for polish, marker in ((False, "o"), (True, "*")):
            rs = [r for r in rows if r["scene"] == scene and r["polish"] == polish and not r["setting"].startswith("reference")]
            if rs:
                ax.scatter([r["fwd_ms_per_step"] for r in rs], [max(r["v0_rel_err"], 1e-16) for r in rs], marker=marker,
                           label=f"{scene}" + (", polish" if polish else ", no polish"))
    ax.axhline(1e-2, color="k", ls="--", lw=1, label="1e-2")
    ax.set(xscale="log", yscale="log", xlabel="forward ms/step while recording (one thread)", ylabel="dL/dv0 error vs converged (relative L2)")
    return _save(fig, (ax,), out_dir, "accuracy_gradient.png")


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _no_minor_labels(ax: Any) -> None:
    """Minor tick labels of short log decades overlap; the grid shows the minor ticks."""
    from matplotlib.ticker import NullFormatter

    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.yaxis.set_minor_formatter(NullFormatter())


# -- the study ------------------------------------------------------------------------------
@dataclass
class Plan:
    """Scenes per part, chosen from the command line (full size or --quick)."""

    forward: list[Scene]
    backward: list[Scene]
    gradient: list[Scene]
    timestep: list[Scene]
    full_gradient_grid: bool = True
    timestep_hs: Sequence[float] = TIMESTEP_HS
    timestep_ref: float = TIMESTEP_REFERENCE_H
    timestep_duration: float = TIMESTEP_DURATION


#: Steps per forward rollout by resolution (full size): long enough for the scene to move
#: through its main motion, short enough that the 48x48 plain-PD sweep stays ~1 min.
FORWARD_STEPS = {12: 200, 24: 100, 48: 50}
#: Backward rollouts: the paper's lengths at 12x12, shorter above (fixed_point at 48x48 falls
#: back to LU on every step, ~0.2 s/step per eps).
BACKWARD_STEPS = {("wind", 12): 200, ("slope", 12): 300, ("wind", 24): 100, ("slope", 24): 100, ("wind", 48): 40, ("slope", 48): 40}


def make_plan(scenes: Sequence[str], res: Sequence[int], quick: bool) -> Plan:
    """The scenes of each part. ``quick``: few steps everywhere, for a smoke run."""
    def steps(full: int, small: int) -> int:
        return small if quick else full

    fwd, bwd, grad, ts = [], [], [], []
    grad_res = 24 if 24 in res else min(res)
    for name in scenes:
        if name in ("wind", "slope"):
            # Slope from rest slides rigidly (PD exact in 1-2 iterations, error 1e-13): random
            # initial velocities make it deform. Wind moves by itself (gravity and wind).
            fwd += [grid_scene(name, r, steps(FORWARD_STEPS.get(r, 50), 10), v_sigma=0.1 if name == "slope" else 0.0) for r in res]
            bwd += [grid_scene(name, r, steps(BACKWARD_STEPS.get((name, r), 40), 10), v_sigma=0.1) for r in res]
        if name == "wind":
            grad.append(Scene(f"wind{grad_res}x{grad_res}", contact_free(load_scene("wind", grad_res)), steps(400, 20)))
            ts.append(grid_scene("wind", grad_res, 0))
        if name == "hat":
            fwd.append(garment_scene("hat", steps(100, 10)))
            grad.append(garment_scene("hat", steps(400, 20), drive=None))
            ts.append(garment_scene("hat", 0))
        if name == "hat_contact":
            fwd.append(garment_scene("hat", steps(100, 10), contact=True))
        if name == "sock":
            grad.append(garment_scene("sock", steps(200, 20), drive=None))
    return Plan(fwd, bwd, grad, ts, full_gradient_grid=not quick,
                timestep_hs=TIMESTEP_HS[:3] if quick else TIMESTEP_HS,
                timestep_ref=1 / 200 if quick else TIMESTEP_REFERENCE_H,
                timestep_duration=0.2 if quick else TIMESTEP_DURATION)


def run_part(part: str, plan: Plan, out_dir: Path, log: Callable[[str], None] = print) -> tuple[list[dict], list[str]]:
    """Runs one part; returns its rows and the plot files it wrote."""
    rows: list[dict] = []
    for scene in getattr(plan, part):
        t = time.perf_counter()
        if part == "forward":
            rows += forward_scene(scene)
        elif part == "backward":
            rows += backward_scene(scene)
        elif part == "gradient":
            rows += gradient_scene(scene, plan.full_gradient_grid)
        else:
            rows += timestep_scene(scene, plan.timestep_hs, plan.timestep_ref, plan.timestep_duration)
        log(f"{part}: {scene.label} done in {time.perf_counter() - t:.0f} s")
    if not rows:
        return rows, []
    plot = {"forward": plot_forward, "backward": plot_backward, "gradient": plot_gradient, "timestep": plot_timestep}[part]
    return rows, plot(rows, out_dir)


# -- report ---------------------------------------------------------------------------------
def _fmt(v: Any) -> str:
    """Table cells: scientific for small/large floats, blank for None."""
    if v is None:
        return ""
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float) and not math.isnan(v):
        if v == 0:
            return "0"
        if abs(v) >= 1e4 or abs(v) < 1e-2:
            return f"{v:.2e}"
        return f"{v:.3g}"
    return str(v)


def table(rows: list[dict], columns: list[str], headers: list[str] | None = None) -> str:
    """A Markdown table of ``rows`` restricted to ``columns``."""
    lines = ["| " + " | ".join(headers or columns) + " |", "|" + "---|" * len(columns)]
    lines += ["| " + " | ".join(_fmt(r.get(c)) for c in columns) + " |" for r in rows]
    return "\n".join(lines)


def forward_section(rows: list[dict]) -> list[str]:
    out = ["## 1. Forward: tolerance and iteration cap, plain PD vs Anderson", "",
           "Per scene: the Pareto front (settings no other setting beats in both ms/step and trajectory error), then "
           "the cheapest setting of each solver at three error levels. `traj_rel_err` = |X - X_ref| / |X_ref - X_0| over "
           "the whole rollout, X_ref = Anderson at tolerance 1e-12 (cap 20000); `reference floor` = the error of a run at "
           "1e-13 against X_ref: errors near it are not resolved. Tolerance = RMS per-coordinate PD update "
           "in metres; `cap N` = tolerance 0, exactly N iterations per step. Initial states: Wind from rest (moved by "
           "gravity and its wind), Slope from seeded random velocities (sigma 0.1 m/s: from rest it slides rigidly and PD is "
           f"exact in 1-2 iterations), Hat with its effectors moving at {GARMENT_DRIVE} m/s; `hat` is the full scene (head, "
           "friction, self-collision), `hat_nocontact` the hanging hat.", "",
           "Reading the plots: where the error sits on a plateau over several settings and then drops by orders of magnitude, "
           "the rollout passes an event it is sensitive to (buckling or snap-through of the hat; wrinkling of the 48x48 cloth, "
           "which has no bending stiffness; a contact switch): near it PD converges slowly, a loose stop lands on a "
           "different state, and the rollouts part. There the error measures the scene's sensitivity more than the per-step "
           "tolerance, and an iteration cap that happens to resolve the event can beat a tolerance.", ""]
    summary = []
    for scene in dict.fromkeys(r["scene"] for r in rows):
        rs = [r for r in rows if r["scene"] == scene and r["sweep"] in ("tolerance", "cap")]
        ref = next(r for r in rows if r["scene"] == scene and r["sweep"] == "reference")
        check = next((r for r in rows if r["scene"] == scene and r["sweep"] == "reference_check"), {})
        front = sorted((r for r in rs if r["pareto"]), key=lambda r: r["ms_per_step"])
        line = {"scene": scene, "steps": ref["steps"], "reference ms/step": ref["ms_per_step"],
                "reference unconverged %": ref["unconverged_pct"], "reference floor": check.get("traj_rel_err"),
                "Pareto front (setting: ms/step, error)": "; ".join(f"{setting_label(r)}: {r['ms_per_step']:.3g}, {r['traj_rel_err']:.1e}" for r in front),
                "AA share of front": f"{sum(r['acceleration'] == 'anderson' for r in front)}/{len(front)}"}
        for level in (1e-2, 1e-4, 1e-6):
            for accel, name in (("none", "plain"), ("anderson", "AA")):
                ok = [r for r in rs if r["acceleration"] == accel and r["traj_rel_err"] <= level]
                best = min(ok, key=lambda r: r["ms_per_step"]) if ok else None
                line[f"{name} ms @ {level:.0e}"] = None if best is None else f"{best['ms_per_step']:.3g} ({setting_label(best)})"
        summary.append(line)
    cols = ["scene", "steps", "reference ms/step", "reference floor", "AA share of front", "plain ms @ 1e-02", "AA ms @ 1e-02", "plain ms @ 1e-04",
            "AA ms @ 1e-04", "plain ms @ 1e-06", "AA ms @ 1e-06"]
    out += ["### Cheapest setting per error level (ms/step, one thread; blank: not reached)", "", table(summary, cols), ""]
    out += ["### Pareto fronts", "", table(summary, ["scene", "Pareto front (setting: ms/step, error)"]), ""]
    out += [f"![{s}](accuracy_forward_{s}.png)" for s in dict.fromkeys(r["scene"] for r in rows)] + [""]
    cols = ["scene", "acceleration", "sweep", "tolerance", "max_iterations", "ms_per_step", "iters_per_step", "unconverged_pct", "traj_rel_err", "pareto"]
    out += ["<details><summary>All forward rows</summary>", "", table(rows, cols), "", "</details>", ""]
    return out


def backward_section(rows: list[dict]) -> list[str]:
    out = ["## 2. Backward: paper Table 1 with our numbers", "",
           f"One recorded rollout per scene at the default forward settings (Anderson 1e-8, recorded steps to {default_record_tolerance():.0e}; seeded "
           "random initial velocities, sigma 0.1 m/s), a controller-style loss (random linear weights on every step's "
           f"positions), adjoint iteration cap {BACKWARD_MAX_ITERATIONS}. `ms/step` = the backward's stage profile summed "
           "(inside Rust); speedup = direct ms / ms in the same run; fail % = steps whose iterative solve stalled, diverged "
           "or hit the cap and fell back to direct (sparse LU); mean iters over the steps that did not fall back (blank: "
           "all fell back). Gradient errors against direct: `all` = x0, v0 and every step's effector targets stacked. "
           "Stage shares: our `solve` includes the fallback LU; the paper splits it into Iter. + Direct. Our fixed_point "
           "stops on the true relative residual |g - H z| / |g| <= eps, which is stricter than a stop on the update size "
           "when the iteration converges slowly (as at 48x48, where P^-1 (dP + dR) has spectral radius close to 1 and "
           "the iteration needs more than the cap), so the paper's eps need not mean the same accuracy.", "",
           TABLE1_CAVEATS, ""]
    t1 = table1_rows(rows)
    out += ["### Table 1 side by side (eps 1e-4 and 1e-6)", "",
            table(t1, list(t1[0].keys()) if t1 else []), ""]
    out += [f"![{t}](accuracy_backward_{t}.png)" for t in dict.fromkeys(r["scene"].rstrip("0123456789x") for r in rows)] + [""]
    cols = ["scene", "steps", "solver", "eps", "ms_per_step", "wall_ms_per_step", "speedup_vs_direct", "fail_pct", "mean_iters",
            "dp_pct", "dr_pct", "solve_pct", "other_pct", "v0_rel_err", "v0_cos", "all_rel_err", "all_cos"]
    out += ["### Full eps sweep", "", table(rows, cols), ""]
    return out


def gradient_section(rows: list[dict]) -> list[str]:
    out = ["## 3. Gradient error caused by the forward tolerance", "",
           "Rollout from seeded random velocities (sigma 0.2 m/s) with the effectors moving (0, -0.003, 0.002) m per step "
           "and a smooth-L1 loss to a target shape on every step (as tests/test_gradient_consistency.py); gradients by the "
           "direct (LU) backward, compared with the gradient of a trajectory converged to 1e-12. `no polish`: recorded "
           "steps stop where unrecorded ones would (record_tolerance = tolerance, same cap); `polish`: the default, "
           f"recorded steps converge to {default_record_tolerance():.0e} (so the polished trajectory does not depend on the tolerance). `fwd ms/step` "
           "is measured while recording, polish included (iterations/step is the noise-free cost). `warned` = the "
           "backward's `warnings` was non-empty.", "",
           "Reading: without polish the error is not monotone in the tolerance: the adjoint linearizes each step at an "
           "unconverged state (where M + h^2 Hess W need not be positive definite) and 400 steps compound it, most where the "
           f"rollout is sensitive (see part 1). With polish every tolerance records the same {default_record_tolerance():.0e} trajectory; its remaining "
           "error against 1e-12 is the scene's own sensitivity to the per-step residual.", ""]
    hat = next((s for s in dict.fromkeys(r["scene"] for r in rows) if s.startswith("hat")), None)
    if hat:
        best = cheapest_within(rows, hat)
        if best:
            out += [f"**Cheapest forward setting whose {hat} gradient (v0 and targets) is within 1e-2 of the converged one: "
                    f"`{best['setting']}` at {best['fwd_ms_per_step']:.3g} ms/step while recording "
                    f"({best['iters_per_step']:.1f} iterations/step; v0 error {best['v0_rel_err']:.1e}, targets error "
                    f"{best['targets_rel_err']:.1e}).**", ""]
        else:
            out += [f"**No setting gets the {hat} gradient within 1e-2.**", ""]
        cpp = []
        for tol, cpp_err in sorted(CPP_HAT_GRADIENT_ERROR.items()):
            def err(pred: Callable[[dict], bool]) -> float | None:
                r = next((r for r in rows if r["scene"] == hat and pred(r)), None)
                return None if r is None else r["v0_rel_err"]
            cpp.append({"tolerance": tol, "reference C++ (plain PD, no polish)": cpp_err,
                        "ours plain, no polish": err(lambda r: r["acceleration"] == "none" and r["tolerance"] == tol and not r["polish"]),
                        "ours AA, no polish": err(lambda r: r["acceleration"] == "anderson" and r["tolerance"] == tol and not r["polish"]),
                        f"ours AA, polish {default_record_tolerance():.0e}": err(lambda r: r["tolerance"] == tol and r["polish"])})
        out += [f"### {hat}: dL/dv0 relative error beside the reference C++ code's (400 steps, exact LU, no clipping; its gradients "
                "are only usable clipped)", "", table(cpp, list(cpp[0].keys())), ""]
    cols = ["scene", "steps", "setting", "fwd_ms_per_step", "iters_per_step", "polish_iters_per_step", "unconverged_pct", "v0_rel_err",
            "v0_cos", "targets_rel_err", "targets_cos", "v0_grad_norm", "warned", "bwd_ms_per_step"]
    out += ["### All settings", "", table(rows, cols), "", "![gradient](accuracy_gradient.png)", ""]
    return out


def timestep_section(rows: list[dict]) -> list[str]:
    out = ["## 4. Time step", "",
           "Fixed simulated duration; error = relative L2 (against the reference's displacement) of the positions at the "
           "common times k * max(h), against a run at a much smaller h (Anderson, tolerance 1e-11). The Hat's effectors move "
           f"at {GARMENT_DRIVE} m/s, Wind is driven by its wind. With first-order implicit Euler the error against a finite "
           "h_ref is overestimated by about 1 / (1 - h_ref/h) (33 % at h = 4 h_ref).", ""]
    cols = ["scene", "one_over_h", "tolerance", "steps", "ms_per_step", "ms_total", "iters_per_step", "rel_err", "final_rel_err"]
    out += [table(rows, cols), ""]
    for scene in dict.fromkeys(r["scene"] for r in rows):
        for tol in sorted({r["tolerance"] for r in rows}):
            rs = sorted((r for r in rows if r["scene"] == scene and r["tolerance"] == tol), key=lambda r: r["h"])
            if len(rs) >= 2:
                order = math.log(rs[-1]["rel_err"] / rs[0]["rel_err"]) / math.log(rs[-1]["h"] / rs[0]["h"])
                out.append(f"- {scene}, tolerance {tol:.0e}: observed order {order:.2f} between h = 1/{rs[-1]['one_over_h']} and "
                           f"1/{rs[0]['one_over_h']}; h = 1/{rs[-1]['one_over_h']}: error {rs[-1]['rel_err']:.1e} in "
                           f"{rs[-1]['ms_total']:.0f} ms; h = 1/{rs[0]['one_over_h']}: error {rs[0]['rel_err']:.1e} in "
                           f"{rs[0]['ms_total']:.0f} ms.")
    out += ["", "![timestep](accuracy_timestep.png)", ""]
    return out


SECTIONS = {"forward": forward_section, "backward": backward_section, "gradient": gradient_section, "timestep": timestep_section}


def write_report(rows: list[dict], meta_block: dict, out_dir: Path, notes: str = "") -> tuple[Path, Path]:
    """Writes ``accuracy_time.json`` (all rows, each with ``part``) and ``accuracy_time.md``
    (one section per part present)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    json_path, md_path = out_dir / f"{NAME}.json", out_dir / f"{NAME}.md"
    json_path.write_text(json.dumps({"meta": meta_block, "rows": rows}, indent=1, default=_json_default) + "\n")
    md = ["# Accuracy vs time", "",
          f"`{meta_block['command']}` — {meta_block['date']}, {meta_block['cpu']}, git {meta_block['git']}"
          + (f", {meta_block['seconds'] / 60:.1f} min" if "seconds" in meta_block else ""), ""]
    for part, pm in meta_block.get("parts", {}).items():
        if pm.get("date") != meta_block["date"]:
            md.append(f"- part `{part}` from an earlier run: `{pm['command']}` — {pm['date']}, git {pm['git']}")
    if notes:
        md += ["", notes.strip(), ""]
    guard = meta_block.get("timing_guard")
    if guard:
        md += [f"Timing guard (this run): {guard['reruns']} reruns of timed runs whose time inside Rust exceeded the "
               f"thread's CPU time by > {int(100 * (DISTURBED_RATIO - 1))} % (another process had the core); "
               f"{guard['disturbed']} measurements were still disturbed after {RERUNS} reruns (the fastest was kept).", ""]
    for part in PARTS:
        prs = [r for r in rows if r["part"] == part]
        if prs:
            md += SECTIONS[part](prs)
    md_path.write_text("\n".join(md) + "\n")
    return json_path, md_path


def _json_default(v: Any) -> Any:
    if isinstance(v, (np.floating, np.integer)):
        return v.item()
    if isinstance(v, np.bool_):
        return bool(v)
    raise TypeError(f"not JSON serializable: {type(v)}")


NOTES = (
    "All runs single-threaded (`parallel=False`) on a shared 2-core machine; times are measured inside Rust (the "
    "simulator's profile) and are noisy (about +-25 %: other jobs share the cores), so compare orders of magnitude and "
    "trends, not single digits. Steps per scene (full run): forward Wind/Slope 12x12: 200, 24x24: 100, 48x48: 50, Hat "
    "(with and without contact): 100; backward Wind 12x12: 200 and Slope 12x12: 300 (the paper's lengths), 24x24: 100, "
    "48x48: 40; gradient Hat: 400, Sock: 200, Wind 24x24: 400; time step: 1 s simulated. `--quick` uses about 10-20 "
    "steps everywhere and a smaller grid of settings."
)


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m diffcloth_gym.bench accuracy", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scene", action="append", default=None,
                   help=f"scenes (repeatable or comma list) from {', '.join(SCENE_NAMES)}; default all")
    p.add_argument("--res", type=int, nargs="+", default=None, help="grid resolutions of Wind and Slope (default 12 24 48; --quick: 12)")
    p.add_argument("--quick", action="store_true", help="few steps and settings: a smoke run")
    p.add_argument("--part", choices=[*PARTS, "all"], action="append", default=None, help="part(s) to run (repeatable; default all)")
    p.add_argument("--out", type=Path, default=None, help="output folder (default benchmarks/results)")
    args = p.parse_args(list(argv))
    args.scene = [s.strip() for a in (args.scene or [",".join(SCENE_NAMES)]) for s in a.split(",") if s.strip()]
    unknown = sorted(set(args.scene) - set(SCENE_NAMES))
    if unknown:
        p.error(f"unknown scene(s) {unknown}; known: {list(SCENE_NAMES)}")
    args.res = args.res or ([12] if args.quick else [12, 24, 48])
    args.part = list(PARTS) if not args.part or "all" in args.part else list(dict.fromkeys(args.part))
    return args


def main(argv: Sequence[str] | None = None) -> int:
    args = parse_args(sys.argv[1:] if argv is None else argv)
    out_dir = args.out or results.RESULTS_DIR
    out_dir.mkdir(parents=True, exist_ok=True)
    plan = make_plan(args.scene, args.res, args.quick)
    command = " ".join(["python -m diffcloth_gym.bench accuracy", *(sys.argv[1:] if argv is None else argv)])
    start = time.perf_counter()
    previous = out_dir / f"{NAME}.json"
    old = json.loads(previous.read_text()) if previous.exists() else {"meta": {}, "rows": []}
    # Parts not run now keep their rows (and their meta) from the earlier run.
    rows = [r for r in old["rows"] if r.get("part") not in args.part]
    part_meta = {p: m for p, m in old["meta"].get("parts", {}).items() if p not in args.part}
    now = results.meta({"command": command})
    for part in args.part:
        t = time.perf_counter()
        part_rows, _ = run_part(part, plan, out_dir, log=lambda s: print(s, flush=True))
        rows += part_rows
        part_meta[part] = dict(now, seconds=round(time.perf_counter() - t, 1), quick=args.quick)
        print(f"part {part}: {time.perf_counter() - t:.0f} s", flush=True)
    now.update(parts=part_meta, seconds=round(time.perf_counter() - start, 1), quick=args.quick,
               threads_used=1, scenes=args.scene, res=args.res, timing_guard=dict(TIMING))
    rows.sort(key=lambda r: PARTS.index(r["part"]))
    json_path, md_path = write_report(rows, now, out_dir, NOTES)
    print(f"wrote {json_path} and {md_path} in {time.perf_counter() - start:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
