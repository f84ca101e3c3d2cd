"""Part 4: error and time against the time step h for a fixed simulated duration."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Sequence

import numpy as np

from benchmarks.accuracy.common import GARMENT_DRIVE, Scene, make_sim, pyplot, rollout, save_plot, table
from benchmarks.measures import trajectory_error

#: Time-step part: simulated duration, time steps, reference time step, solver tolerances.
TIMESTEP_DURATION = 1.0
TIMESTEP_HS = (1 / 25, 1 / 50, 1 / 100, 1 / 200, 1 / 400)
TIMESTEP_REFERENCE_H = 1 / 1600
TIMESTEP_TOLERANCES = (1e-8, 1e-10)
TIMESTEP_REFERENCE_SOLVER = dict(acceleration="anderson", tolerance=1e-11, max_iterations=5000)


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
    plt = pyplot()
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4.2))
    for scene in dict.fromkeys(r["scene"] for r in rows):
        for tol, ls in zip(sorted({r["tolerance"] for r in rows}), ("--", "-", ":")):
            rs = sorted((r for r in rows if r["scene"] == scene and r["tolerance"] == tol), key=lambda r: r["h"])
            label = f"{scene}, tol {tol:.0e}"
            a.plot([r["h"] for r in rs], [r["rel_err"] for r in rs], "o" + ls, label=label)
            b.plot([r["ms_total"] for r in rs], [r["rel_err"] for r in rs], "o" + ls, label=label)
    a.set(xscale="log", yscale="log", xlabel="time step h (s)", ylabel="error vs h_ref (relative L2, common times)")
    b.set(xscale="log", yscale="log", xlabel="forward time for the whole duration (ms, one thread)", ylabel="error")
    return save_plot(fig, (a, b), out_dir, "accuracy_timestep.png")


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
