"""Part 2, backward: the paper's Table 1 with our numbers. Direct vs fixed_point vs krylov
adjoint solves over a range of eps on Wind and Slope; time, stage shares, fail %, speedup,
gradient error against direct; the paper's numbers beside ours."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Sequence

import numpy as np

from benchmarks.accuracy.common import (
    Scene,
    gradient_tolerance,
    initial_velocities,
    make_sim,
    no_minor_labels,
    pyplot,
    table,
    undisturbed,
)
from benchmarks.measures import compare
from diffcloth_gym import Simulator

#: Adjoint tolerances of the backward sweep (the paper varied 1e-1 ... 1e-9).
BACKWARD_EPS = (1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9)
#: Iteration cap of the iterative adjoint solvers (the API default).
BACKWARD_MAX_ITERATIONS = 500
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


def record_for_backward(scene: Scene) -> tuple[Simulator, np.ndarray]:
    """Records a rollout at the gradient solver preset (Anderson, tolerance 1e-11) from seeded random velocities, and a controller-style loss: seeded random linear
    weights on the positions of every step (as scripts/bench_backward.py)."""
    sim = make_sim(scene.config, preset="gradient")
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
    plt = pyplot()
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
            no_minor_labels(ax)
            ax.legend(fontsize=7)
        fig.tight_layout()
        name = f"accuracy_backward_{test}.png"
        fig.savefig(out_dir / name, dpi=110)
        plt.close(fig)
        files.append(name)
    return files


def backward_section(rows: list[dict]) -> list[str]:
    out = ["## 2. Backward: paper Table 1 with our numbers", "",
           f"One recorded rollout per scene at the gradient solver preset (Anderson, tolerance {gradient_tolerance():.0e}, as the default's polished recorded steps before; seeded "
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
