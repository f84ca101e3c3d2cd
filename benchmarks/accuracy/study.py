"""The study: which scenes each part runs (:func:`make_plan`), the command line, and the
report ``accuracy_time.{json,md}`` (one section per part)."""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from benchmarks import results_io
from benchmarks.accuracy.backward import backward_scene, backward_section, plot_backward
from benchmarks.accuracy.common import DISTURBED_RATIO, RERUNS, TIMING, Scene, garment_scene, grid_scene, hat_on_head_scene, sphere_scene
from benchmarks.accuracy.forward import forward_scene, forward_section, plot_forward
from benchmarks.accuracy.gradient import gradient_scene, gradient_section, plot_gradient
from benchmarks.accuracy.timestep import (
    TIMESTEP_DURATION,
    TIMESTEP_HS,
    TIMESTEP_REFERENCE_H,
    plot_timestep,
    timestep_scene,
    timestep_section,
)
from diffcloth_gym.scenes import contact_free, load_scene

NAME = "accuracy_time"
PARTS = ("forward", "backward", "gradient", "timestep")
SCENE_NAMES = ("wind", "slope", "hat", "hat_contact", "sock", "sphere")


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
#: Sphere drops (forward part only) at these resolutions when asked for, and their steps: the
#: drape is chaotic after ~30 steps at 48 x 48 (``gradient_horizon``), so errors there measure
#: the scene's sensitivity, not the solver.
SPHERE_STEPS = {24: 100, 48: 50}
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
            grad.append(Scene(f"wind{grad_res}x{grad_res}", contact_free(load_scene("wind", rows=grad_res, cols=grad_res)), steps(400, 20)))
            ts.append(grid_scene("wind", grad_res, 0))
        if name == "hat":
            fwd.append(garment_scene("hat", steps(100, 10)))
            grad.append(garment_scene("hat", steps(400, 20), drive=None))
            ts.append(garment_scene("hat", 0))
        if name == "hat_contact":
            fwd.append(hat_on_head_scene(steps(120, 10)))
        if name == "sphere":
            fwd += [sphere_scene(r, steps(SPHERE_STEPS[r], 10)) for r in res if r in SPHERE_STEPS]
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
    "contact-free: 100, Hat landing on the head: 120, sphere drop 24x24: 100, 48x48: 50; backward Wind 12x12: 200 and Slope 12x12: 300 (the paper's lengths), 24x24: 100, "
    "48x48: 40; gradient Hat: 400, Sock: 200, Wind 24x24: 400; time step: 1 s simulated. `--quick` uses about 10-20 "
    "steps everywhere and a smaller grid of settings."
)


def parse_args(argv: Sequence[str]) -> argparse.Namespace:
    p = argparse.ArgumentParser(prog="python -m benchmarks accuracy", description=sys.modules[__package__].__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scene", action="append", default=None,
                   help=f"scenes (repeatable or comma list) from {', '.join(SCENE_NAMES)}; default all")
    p.add_argument("--res", type=int, nargs="+", default=None, help="grid resolutions of Wind and Slope (default 12 24 48; --quick: 12)")
    p.add_argument("--quick", action="store_true", help="few steps and settings: a smoke run")
    p.add_argument("--part", choices=[*PARTS, "all"], action="append", default=None, help="part(s) to run (repeatable; default all)")
    p.add_argument("--out", type=Path, default=None, help="output folder (default benchmarks/results)")
    p.add_argument("--note", default="", help="text for the report, below the standard notes (e.g. what changed since the last run)")
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
    out_dir = args.out or results_io.RESULTS_DIR
    out_dir.mkdir(parents=True, exist_ok=True)
    plan = make_plan(args.scene, args.res, args.quick)
    command = " ".join(["python -m benchmarks accuracy", *(sys.argv[1:] if argv is None else argv)])
    start = time.perf_counter()
    previous = out_dir / f"{NAME}.json"
    old = json.loads(previous.read_text()) if previous.exists() else {"meta": {}, "rows": []}
    # Parts not run now keep their rows (and their meta) from the earlier run.
    rows = [r for r in old["rows"] if r.get("part") not in args.part]
    part_meta = {p: m for p, m in old["meta"].get("parts", {}).items() if p not in args.part}
    now = results_io.meta({"command": command})
    for part in args.part:
        t = time.perf_counter()
        part_rows, _ = run_part(part, plan, out_dir, log=lambda s: print(s, flush=True))
        rows += part_rows
        part_meta[part] = dict(now, seconds=round(time.perf_counter() - t, 1), quick=args.quick)
        print(f"part {part}: {time.perf_counter() - t:.0f} s", flush=True)
    now.update(parts=part_meta, seconds=round(time.perf_counter() - start, 1), quick=args.quick,
               threads_used=1, scenes=args.scene, res=args.res, timing_guard=dict(TIMING))
    rows.sort(key=lambda r: PARTS.index(r["part"]))
    json_path, md_path = write_report(rows, now, out_dir, NOTES + ("\n\n" + args.note if args.note else ""))
    print(f"wrote {json_path} and {md_path} in {time.perf_counter() - start:.0f} s")
    return 0
