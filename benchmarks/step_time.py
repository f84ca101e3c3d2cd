"""Forward step benchmark: ms/step, PD iterations/step and trajectory error per solver setting.

For each scene (Wind 12/24/48, Hat) and solver (plain PD, Anderson) at a loose and a tight
tolerance, single thread and all threads, runs a rollout and reports the time inside Rust
(the simulator's own profile, no Python overhead) and the trajectory error against a tightly
converged run (relative L2 over the whole rollout, relative to the reference displacement).

"At the reference's accuracy": the reference C++ code runs plain PD with 111-219 iterations per
step on Hat at its tolerance 1e-8. Plain PD with a fixed 150 iterations per step
(`plain@150it`, the same algorithm) gives that accuracy here; the `anderson@match` row is the
loosest Anderson tolerance whose trajectory error is at most that.

With `--suite contact` (or `all`, the default) it also times the contact scenes (Slope
12/24/48, Sphere, Bowl, Hat, Sock) at the default solver settings: ms/step, contacts per step by
branch, share of time per stage, and `contact_adds_pct` = time in detection + contact solve
relative to the rest of the step (target at Slope, every node in contact: <= 50 %).

Writes benchmarks/results/step_time.{json,md}; a suite run replaces only its own label's rows
of that suite (``--label``, default ``current``), so runs of different builds sit side by side. `--mesh PATH` times an OBJ mesh instead, into step_time_mesh.{json,md} (e.g.
the reference meshes) with the Wind scene's material and its two top corners pinned.

Run: .venv/bin/python scripts/bench_step.py (or python -m benchmarks step_time) [--suite forward|contact|all]
[--quick] [--mesh PATH ...] [--label L] [--note TEXT]
"""

from __future__ import annotations

import argparse
import copy
import os
from pathlib import Path
from typing import Sequence

import numpy as np

from benchmarks import results_io
from benchmarks.measures import trajectory_error
from diffcloth_gym import Simulator
from diffcloth_gym.scenes import contact_free, load_scene


def scene_configs(args) -> list[tuple[str, dict]]:
    wind = load_scene("wind")
    hat = load_scene("hat")
    out = []
    if args.mesh:
        for path in args.mesh:
            cfg = copy.deepcopy(wind)
            cfg["mesh"] = {"kind": "obj", "path": str(Path(path).resolve())}
            cfg["name"] = Path(path).stem
            out.append((Path(path).stem, cfg))
        return out
    for res in args.res:
        out.append((f"wind{res}x{res}", load_scene("wind", rows=res, cols=res)))
    # The forward suite times the core solver: the hat hanging from its handles, contact off
    # (the contact suite runs the full scene with the head and self-collision).
    out.append(("hat_nocontact", contact_free(hat)))
    return out


def rollout(cfg: dict, steps: int, solver: dict, parallel: bool) -> tuple[np.ndarray, dict, int]:
    sim = Simulator.from_config(cfg)
    sim.set_solver(parallel=parallel, **solver)
    traj = np.empty((steps + 1, sim.num_nodes, 3))
    traj[0] = sim.positions
    unconverged = 0
    for n in range(steps):
        stats = sim.step()
        unconverged += not stats["converged"]
        traj[n + 1] = sim.positions
    return traj, sim.profile(), unconverged


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--steps", type=int, default=100)
    p.add_argument("--res", type=int, nargs="*", default=[12, 24, 48])
    p.add_argument("--mesh", nargs="*", help="OBJ meshes to time instead of the built-in scenes")
    p.add_argument("--quick", action="store_true", help="fewer steps, for a smoke run")
    p.add_argument("--out", default=None, help="output folder (default benchmarks/results)")
    p.add_argument("--suite", choices=["forward", "contact", "all"], default="all")
    p.add_argument("--label", default="current", help="rows of this run (a rerun of a label replaces its rows; others stay)")
    p.add_argument("--note", default="", help="what this run measures (listed with its command above the table)")
    args = p.parse_args(argv)
    steps = 20 if args.quick else args.steps
    out_dir = Path(args.out) if args.out else results_io.RESULTS_DIR
    rows = []
    if args.suite in ("forward", "all"):
        rows += forward_rows(args, steps)
    if args.suite in ("contact", "all") and not args.mesh:
        rows += contact_rows(args)
    rows = [{"label": args.label, **r} for r in rows]
    notes = (
        f"Forward suite: {steps} steps per rollout; time is inside Rust (profile total), `threads` = 1 (serial "
        f"local step) or all ({os.cpu_count()}: parallel local step for >= 2048 constraints). `traj_rel_err` = "
        "norm(X - X_ref) / norm(X_ref - X_0) over the rollout, X_ref = Anderson at tolerance 1e-13. Tolerance = "
        "RMS per-coordinate PD update in metres. Reference C++ (single thread, tol 1e-8): Hat 42-86 ms/step "
        "(111-219 iterations, 0.39 ms/iteration); Wind 12/24/48: 2.1 / 26 / 264 ms/step; Slope 12/24/48: "
        "0.22 / 1.5 / 9.1 ms/step; Sock 164 ms/step. Contact suite: each scene's default solver (Anderson, tolerance 1e-8, "
        "its contact response), one thread; `contact_adds_pct` = (detection + contact solve) / (rest of the step). "
        "Iteration counts are exact; times depend on the machine's load: compare rows of one run."
    )
    meta_block = results_io.meta({"steps": steps, "note": args.note} if args.note else {"steps": steps})
    if args.mesh:
        # A file of its own: the mesh rows must not replace the built-in scenes' labelled runs.
        out = results_io.write("step_time_mesh", rows, meta_block, "Forward step time (OBJ meshes)", notes, out_dir=out_dir)
    else:
        # A suite run replaces its own label's rows of that suite; the other rows keep their run.
        out = results_io.write_merged("step_time", rows, lambda r: (r.get("label"), r.get("suite", "forward")),
                                      meta_block, "Forward step time", notes, out_dir=out_dir)
    print(results_io.markdown_table(rows))
    print(f"wrote {out}")
    return 0


CONTACT_SCENES = [("slope", 12, 100), ("slope", 24, 100), ("slope", 48, 100), ("sphere", None, 150), ("bowl", None, 100), ("hat", None, 100), ("sock", None, 100)]


def contact_rows(args) -> list[dict]:
    rows = []
    for name, res, steps in CONTACT_SCENES:
        cfg = load_scene(name, rows=res, cols=res) if res else load_scene(name)
        steps = 20 if args.quick else steps
        sim = Simulator.from_config(cfg)
        sim.set_solver(parallel=False)
        for _ in range(steps):
            sim.step()
        p = sim.profile()
        total = p["total_s"]
        contact_s = p["detection_s"] + p["contact_s"]
        contacts = p["contacts_take_off"] + p["contacts_stick"] + p["contacts_slip"]
        rows.append({
            "suite": "contact",
            "scene": f"{name}{res}x{res}" if res else name,
            "nodes": sim.num_nodes,
            "dof": 3 * sim.num_nodes,
            "solver": "anderson",
            "tolerance": sim.solver()["tolerance"],
            "threads": 1,
            "ms_per_step": 1e3 * total / steps,
            "iters_per_step": p["iterations"] / steps,
            "ms_per_iter": 1e3 * total / max(p["iterations"], 1),
            "contacts_per_step": contacts / steps,
            "stick_per_step": p["contacts_stick"] / steps,
            "slip_per_step": p["contacts_slip"] / steps,
            "local_pct": 100 * p["local_s"] / total,
            "global_pct": 100 * p["global_s"] / total,
            "detection_pct": 100 * p["detection_s"] / total,
            "contact_pct": 100 * p["contact_s"] / total,
            "contact_adds_pct": 100 * contact_s / max(total - contact_s, 1e-12),
            "unconverged_pct": 100.0 * p["unconverged_steps"] / steps,
        })
        print(f"{rows[-1]['scene']}: done", flush=True)
    return rows


def forward_rows(args, steps) -> list[dict]:
    rows = []
    for name, cfg in scene_configs(args):
        ref, _, _ = rollout(cfg, steps, dict(tolerance=1e-13, max_iterations=20000, acceleration="anderson"), True)
        nodes = ref.shape[1]
        settings = [
            ("plain", dict(acceleration="none", tolerance=1e-5, max_iterations=2000)),
            ("plain", dict(acceleration="none", tolerance=1e-8, max_iterations=2000)),
            ("plain@150it", dict(acceleration="none", tolerance=0.0, max_iterations=150)),
            ("anderson", dict(acceleration="anderson", tolerance=1e-5, max_iterations=2000)),
            ("anderson", dict(acceleration="anderson", tolerance=1e-8, max_iterations=2000)),
        ]
        match_err = None
        for solver_name, solver in settings:
            for parallel in (False, True):
                traj, prof, unconv = rollout(cfg, steps, solver, parallel)
                err = trajectory_error(traj, ref)
                if solver_name == "plain@150it":
                    match_err = err
                rows.append(row(name, nodes, solver_name, solver, parallel, prof, unconv, steps, err))
        # The loosest Anderson tolerance at the reference's accuracy (plain PD, 150 iterations).
        for tol in [1e-4, 3e-5, 1e-5, 3e-6, 1e-6, 3e-7, 1e-7, 3e-8, 1e-8, 3e-9, 1e-9, 1e-10]:
            solver = dict(acceleration="anderson", tolerance=tol, max_iterations=2000)
            traj, prof, unconv = rollout(cfg, steps, solver, False)
            err = trajectory_error(traj, ref)
            if err <= match_err:
                for parallel in (False, True):
                    traj, prof, unconv = rollout(cfg, steps, solver, parallel)
                    rows.append(row(name, nodes, "anderson@match", solver, parallel, prof, unconv, steps, trajectory_error(traj, ref)))
                break
        print(f"{name}: done ({nodes} nodes)", flush=True)
    return rows


def row(name, nodes, solver_name, solver, parallel, prof, unconv, steps, err) -> dict:
    return {
        "suite": "forward",
        "scene": name,
        "nodes": nodes,
        "dof": 3 * nodes,
        "solver": solver_name,
        "tolerance": solver["tolerance"],
        "threads": os.cpu_count() if parallel else 1,
        "ms_per_step": 1e3 * prof["total_s"] / steps,
        "iters_per_step": prof["iterations"] / steps,
        "ms_per_iter": 1e3 * prof["total_s"] / max(prof["iterations"], 1),
        "local_pct": 100 * prof["local_s"] / prof["total_s"],
        "global_pct": 100 * prof["global_s"] / prof["total_s"],
        "unconverged_pct": 100.0 * unconv / steps,
        "traj_rel_err": err,
    }
