"""Part 3: the gradient error caused by the forward tolerance (with and without the recording
polish), against the gradient of a converged trajectory (Hat, Sock, Wind 24x24)."""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np

from benchmarks.accuracy.common import Scene, gradient_preset, gradient_tolerance, make_sim, pyplot, save_plot, table, undisturbed
from benchmarks.measures import compare

#: Gradient part: the converged trajectory the gradients are compared with (as
#: tests/test_gradient_consistency.py).
GRADIENT_REFERENCE = dict(acceleration="anderson", tolerance=1e-12, max_iterations=5000)
#: Per-step effector motion of the gradient part (as tests/test_gradient_consistency.py).
GRADIENT_DRIVE_PER_STEP = np.array([0.0, -0.003, 0.002])
#: The reference C++ code's Hat gradient (w.r.t. v0, 400 steps, exact LU backward, no clipping)
#: relative to a 1e-11-converged trajectory's, per forward tolerance (DESIGN.md section 3).
CPP_HAT_GRADIENT_ERROR = {1e-8: 1.7e10, 1e-6: 3e83, 1e-4: 6e129}


def gradient_settings(full: bool) -> list[tuple[str, dict]]:
    """(label, set_solver kwargs) of the gradient part. Recorded steps converge like every
    other step (one trajectory whether recorded or not): each row is one tolerance or cap, and
    the last is the ``gradient`` solver preset (what ``polish`` meant when recorded steps were
    converged further than plain ones: the column name is kept for the committed results)."""
    def loose(accel: str, tol: float, cap: int) -> dict:
        return dict(acceleration=accel, tolerance=tol, max_iterations=cap)

    tols = (1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10) if full else (1e-4, 1e-6, 1e-8, 1e-10)
    caps = (20, 50, 100) if full else (50,)
    out = [(f"AA {t:.0e}, no polish", loose("anderson", t, 300)) for t in tols]
    out += [(f"AA cap {c}, no polish", loose("anderson", 0.0, c)) for c in caps]
    if full:
        # Plain PD without polish: the reference C++ code's algorithm and regime.
        out += [(f"plain {t:.0e}, no polish", loose("none", t, 2000)) for t in (1e-6, 1e-8)]
    rt = gradient_tolerance()
    out += [(f"AA {rt:.0e}, preset gradient", dict(acceleration="anderson", tolerance=rt, max_iterations=2000,
                                                   polish=True))]
    return out


def gradient_run(scene: Scene, solver: dict) -> dict:
    """Records the scene's rollout (seeded random v0, effectors driven as in
    tests/test_gradient_consistency.py), takes a smooth-L1 loss to a target shape on every
    step and returns the direct-backward gradients plus the forward cost while recording."""
    sim = make_sim(scene.config, **{k: v for k, v in solver.items() if k != "polish"})
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
    polish = bool(solver.get("polish"))
    return {
        "part": "gradient",
        "scene": scene.label,
        "steps": steps,
        "setting": label,
        "acceleration": solver["acceleration"],
        "tolerance": solver["tolerance"],
        "max_iterations": solver["max_iterations"],
        "polish": polish,
        "fwd_ms_per_step": 1e3 * prof["total_s"] / steps,
        "iters_per_step": prof["iterations"] / steps,
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


def plot_gradient(rows: list[dict], out_dir: Path) -> list[str]:
    """v0-gradient error against forward ms/step (while recording), one line per scene."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.8))
    for scene in dict.fromkeys(r["scene"] for r in rows):
        for polish, marker in ((False, "o"), (True, "*")):
            rs = [r for r in rows if r["scene"] == scene and r["polish"] == polish and not r["setting"].startswith("reference")]
            if rs:
                ax.scatter([r["fwd_ms_per_step"] for r in rs], [max(r["v0_rel_err"], 1e-16) for r in rs], marker=marker,
                           label=f"{scene}" + (", polish" if polish else ", no polish"))
    ax.axhline(1e-2, color="k", ls="--", lw=1, label="1e-2")
    ax.set(xscale="log", yscale="log", xlabel="forward ms/step while recording (one thread)", ylabel="dL/dv0 error vs converged (relative L2)")
    return save_plot(fig, (ax,), out_dir, "accuracy_gradient.png")


def gradient_section(rows: list[dict]) -> list[str]:
    out = ["## 3. Gradient error caused by the forward tolerance", "",
           "Rollout from seeded random velocities (sigma 0.2 m/s) with the effectors moving (0, -0.003, 0.002) m per step "
           "and a smooth-L1 loss to a target shape on every step (as tests/test_gradient_consistency.py); gradients by the "
           "direct (LU) backward, compared with the gradient of a trajectory converged to 1e-12. Recorded steps converge "
           "like unrecorded ones (one trajectory whether recorded or not); `no polish` rows stop at the setting shown, "
           f"`polish` is the `gradient` solver preset (tolerance {gradient_tolerance():.0e}, cap "
           f"{gradient_preset()['max_iterations']}; 2000 before session 14). Results committed before "
           "the retirement of `record_tolerance` show `polish` rows at two plain tolerances with recorded steps converged to "
           "1e-11: the same trajectory as the preset. `fwd ms/step` is measured while recording. `warned` = the "
           "backward's `warnings` was non-empty.", "",
           "Reading: without polish the error is not monotone in the tolerance: the adjoint linearizes each step at an "
           "unconverged state (where M + h^2 Hess W need not be positive definite) and 400 steps compound it, most where the "
           "rollout is sensitive (see part 1). The preset's remaining "
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
                        f"ours AA, preset gradient {gradient_tolerance():.0e}": err(lambda r: r["polish"])})
        out += [f"### {hat}: dL/dv0 relative error beside the reference C++ code's (400 steps, exact LU, no clipping; its gradients "
                "are only usable clipped)", "", table(cpp, list(cpp[0].keys())), ""]
    cols = ["scene", "steps", "setting", "fwd_ms_per_step", "iters_per_step", "unconverged_pct", "v0_rel_err",
            "v0_cos", "targets_rel_err", "targets_cos", "v0_grad_norm", "warned", "bwd_ms_per_step"]
    out += ["### All settings", "", table(rows, cols), "", "![gradient](accuracy_gradient.png)", ""]
    return out
