"""The suite: every case by name (:data:`CASES`), :func:`run_case`, and the benchmark entry
point ``python -m benchmarks stability`` that writes ``benchmarks/results/stability.{json,md}``."""

from __future__ import annotations

import argparse
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from benchmarks import results_io
from benchmarks.stability import cases
from benchmarks.stability.checks import ISSUES, evaluate, known_issue
from benchmarks.stability.garments import case_hat_random, case_sock_random
from benchmarks.stability.metrics import ENERGY_BOUND, LAYER_FRACTION, PENETRATION_SLACK_M, SELF_FRACTION


@dataclass(frozen=True)
class Case:
    """A named case: ``run(size, workdir)`` returns its result dict."""

    name: str
    run: Callable[[str, Path], dict]
    doc: str


def _case(name: str, fn: Callable[..., dict], **kwargs: Any) -> Case:
    return Case(name, lambda size, workdir: fn(size, workdir, **kwargs), (fn.__doc__ or "").strip())


#: Every case of the suite, by name.
CASES: dict[str, Case] = {c.name: c for c in [
    _case("large_step_pinned_h30", cases.case_large_step_pinned, h=1 / 30),
    _case("large_step_pinned_h10", cases.case_large_step_pinned, h=1 / 10),
    _case("large_step_sphere_h30", cases.case_large_step_sphere, h=1 / 30),
    _case("large_step_sphere_h10", cases.case_large_step_sphere, h=1 / 10),
    _case("large_step_sphere_h30_delassus", cases.case_large_step_sphere, h=1 / 30, response="delassus"),
    _case("large_step_sphere_h10_delassus", cases.case_large_step_sphere, h=1 / 10, response="delassus"),
    _case("large_step_sphere_h30_inertia", cases.case_large_step_sphere, h=1 / 30, response="inertia"),
    _case("large_step_sphere_h10_inertia", cases.case_large_step_sphere, h=1 / 10, response="inertia"),
    _case("large_step_slope_h30", cases.case_large_step_slope, h=1 / 30),
    _case("large_step_slope_h10", cases.case_large_step_slope, h=1 / 10),
    _case("soft_hanging", cases.case_soft_hanging),
    _case("fast_end_effectors", cases.case_fast_end_effectors),
    _case("sphere_mu0", cases.case_sphere_friction, mu=0.0),
    _case("sphere_mu2", cases.case_sphere_friction, mu=2.0),
    _case("slope_stick_slip", cases.case_slope_stick_slip),
    _case("bowl_crumple", cases.case_bowl_crumple),
    _case("pyramid_crumple", cases.case_pyramid_crumple),
    _case("obj_degenerate", cases.case_obj_degenerate),
    _case("obj_sliver_1e-4", cases.case_obj_sliver, aspect=1e-4, expect="simulated"),
    _case("obj_sliver_1e-5", cases.case_obj_sliver, aspect=1e-5, expect="simulated"),
    _case("obj_sliver_1e-6", cases.case_obj_sliver, aspect=1e-6, expect="rejected"),
    _case("obj_sliver_1e-8", cases.case_obj_sliver, aspect=1e-8, expect="rejected"),
    _case("sticking_contact_loop", cases.case_sticking_contact_loop),
    _case("hat_random", case_hat_random),
    _case("sock_random", case_sock_random),
]}


def run_case(name: str, size: str = "ci", workdir: Path | None = None) -> dict:
    """Runs one case; ``workdir`` holds its temporary files (a fresh temporary folder if None)."""
    case = CASES[name]
    if workdir is not None:
        out = case.run(size, Path(workdir))
    else:
        with tempfile.TemporaryDirectory(prefix=f"stability_{name}_") as tmp:
            out = case.run(size, Path(tmp))
    return {"case": name, "size": size, **out}


COLUMNS = ["case", "steps", "max_penetration_m", "max_layer_intrusion_m", "thickness_m", "min_self_distance_m",
           "self_radius_m", "max_energy_ratio", "max_stretch", "unconverged_steps", "self_contacts",
           "backward_steps", "fallbacks", "nan_count", "grad_warnings", "failed", "wall_s"]


def main(argv: list[str] | None = None) -> int:
    """``python -m benchmarks stability [--full] [--case NAME ...] [--out DIR]``."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks stability", description=__doc__.splitlines()[0])
    parser.add_argument("--full", action="store_true", help="the issue's sizes (default: the CI sizes)")
    parser.add_argument("--case", action="append", choices=sorted(CASES), help="run only this case (repeatable)")
    parser.add_argument("--out", type=Path, default=None, help="output folder (default benchmarks/results)")
    args = parser.parse_args(argv)
    size = "full" if args.full else "ci"
    rows = []
    for name in args.case or list(CASES):
        print(f"[stability] {name} ({size}) ...", flush=True)
        r = run_case(name, size)
        evaluation = evaluate(r)
        r["evaluation"] = {k: {"ok": ok, "message": msg} for k, (ok, msg) in evaluation.items()}
        failed = [k for k, (ok, _) in evaluation.items() if not ok]
        r["failed"] = ", ".join(f"{k} ({known_issue(name, k, size)})" if known_issue(name, k, size) else k
                                for k in failed) or "-"
        print(f"[stability] {name}: {r['steps']} steps, {r['wall_s']:.1f} s, failed: {r['failed']}", flush=True)
        rows.append(r)
    notes = (
        f"Hard-case stability suite at {size} size (`benchmarks/stability/`; each case's docstring says "
        f"what it runs and checks). Penetration: depth inside an obstacle's surface (bound {PENETRATION_SLACK_M:g} m); "
        f"layer intrusion: depth into the `contact.thickness` layer (bound {LAYER_FRACTION:g} x thickness); "
        f"self pairs: closest nodes sharing no triangle (bound radius x {1 - SELF_FRACTION:g}); energy ratio: "
        f"max E(t)/E(0) with potential from the run's lowest point (unforced cases, bound {ENERGY_BOUND}); fallbacks: "
        f"Krylov backward solves that fell back to LU; `failed`: generic and physical checks that do not hold "
        f"(in parentheses: the known simulator bug, below). Per-case details (every check's message, the slope "
        f"sweep, gradient warnings) are in the JSON.\n\nKnown simulator bugs:\n\n"
        + "\n".join(f"- `{k}`: {title}. {details}" for k, (title, details) in ISSUES.items())
    )
    path = results_io.write("stability", rows, results_io.meta({"size": size}), "Stability suite", notes=notes,
                         columns=COLUMNS, out_dir=args.out)
    print(f"wrote {path} and {path.with_suffix('.md')}")
    return 0
