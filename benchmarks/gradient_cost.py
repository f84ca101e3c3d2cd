"""The cost of a trustworthy gradient (issue 15): per scene, the recorded forward, its Newton
polish and the backward in ms/step with their iteration counts, at the accuracy the envs use,
and the gradient's error against a tightly converged reference.

Scenes (one thread, release build):

- ``hat``: Hat-v0's scene and solver settings (head, self-collision, Newton polish, the
  Delassus contact response); the hat starts straight above the head (Hat-v0 start (0, 0)) and
  its two effectors carry it onto the head along straight lines to the target's handle
  positions over 250 steps, then hold: 400 steps, about half of them in contact.
- ``sock``: Sock-v0's scene and settings; the four effectors move in straight lines from
  TEST_STARTS[0] to the worn sock's handle positions over the 400 steps (dragging the
  opening over the foot: contact-rich).
- ``wind24x24``: the wind scene at 24 x 24 nodes, 100 steps.
- ``sphere24/48/96``: the sphere scene at that many nodes a side, placed just above the sphere
  (its lowest node 0.03 over the contact layer) at the speed of the shipped 0.6 m drop, so
  that contact starts in the first steps.

Settings: ``env`` (every env's rule: tolerance 1e-10 for plain and recorded steps, cap 10000 (2000 before session 12),
the env's polish: Hat-v0 ``semismooth``, Sock-v0 none, ``newton`` for the scenes without an
env), ``semismooth`` (the same with the semismooth contact polish, where that is not the env's) and ``gradient`` (the library's gradient preset: Anderson, 1e-11, no
polish). The reference for each scene is the same rollout at tolerance 1e-13 (cap 20000),
backward with the direct solver. Loss: random linear weights on every step's positions
(controller style); the gradient is d loss / d(x0, v0, attachment targets of every step).
``grad_err`` = max |g - g_ref| / max |g_ref| (the error against the gradient's largest entry),
``grad_rel_l2`` = |g - g_ref| / |g_ref|. Timings are profile totals inside Rust (forward) and
wall time of ``backward`` (backward); iteration counts are exact.

Writes benchmarks/results/gradient_cost.{json,md}. Rows carry a ``label`` (``--label``,
default ``current``): a run replaces only its own label's rows, so a ``before`` and an
``after`` run sit side by side.
Run: .venv/bin/python -m benchmarks gradient_cost [--label L] [--scenes hat sock ...] [--quick]
"""

from __future__ import annotations

import argparse
import time
from typing import Sequence

import numpy as np

from benchmarks import results_io
from diffcloth_gym import Simulator
from diffcloth_gym.envs.engine import DEFAULT_MAX_ITERATIONS, DEFAULT_TOLERANCE, ClothEngine
from diffcloth_gym.envs.hat_v0 import HatTask
from diffcloth_gym.envs.sock_v0 import TEST_STARTS as SOCK_STARTS, SockTask
from diffcloth_gym.scenes import load_scene

ENV_SETTINGS = dict(tolerance=DEFAULT_TOLERANCE, record_tolerance=DEFAULT_TOLERANCE,
                    max_iterations=DEFAULT_MAX_ITERATIONS, record_max_iterations=DEFAULT_MAX_ITERATIONS)
GRADIENT_SETTINGS = dict(preset="gradient", polish="none")
REFERENCE_SETTINGS = dict(tolerance=1e-13, record_tolerance=1e-13, max_iterations=20000,
                          record_max_iterations=20000)
SETTINGS = {"env": ENV_SETTINGS, "semismooth": {**ENV_SETTINGS, "polish": "semismooth"},
            "gradient": GRADIENT_SETTINGS}


class Case:
    """One scene: its config, start state and per-step attachment targets (or None)."""

    def __init__(self, name, cfg, steps, x0=None, v0=None, targets=None, env=False):
        # An env's scene keeps the env's polish (none if it sets none); the scenes without an
        # env polish contact-free steps with Newton, as Hat-v0 did.
        solver = dict(cfg.get("solver", {}))
        solver["polish"] = solver.get("polish", "none") if env else solver.get("polish", "newton")
        cfg = {**cfg, "solver": solver}
        self.name, self.cfg, self.steps = name, cfg, steps
        self.x0, self.v0, self.targets = x0, v0, targets


def _line(a: np.ndarray, b: np.ndarray, steps: int, over: int) -> np.ndarray:
    """Targets moving from a to b in `over` steps, then held, (steps, k, 3)."""
    s = np.minimum(np.arange(1, steps + 1) / over, 1.0)[:, None, None]
    return a[None] + s * (b - a)[None]


def hat_case(steps: int) -> Case:
    engine = ClothEngine(HatTask, 1)
    start = engine.task.start((0.0, 0.0))
    handles = engine.task.handles
    end = engine.task.target_np[handles]
    return Case("hat", engine.scene, steps, start.x, start.v, _line(start.control, end, steps, 250), env=True)


def sock_case(steps: int) -> Case:
    engine = ClothEngine(SockTask, 1)
    start = engine.task.start(SOCK_STARTS[0])
    end = engine.task.worn[engine.task.handles]
    return Case("sock", engine.scene, steps, start.x, start.v, _line(start.control, end, steps, 400), env=True)


def sphere_case(res: int, steps: int) -> Case:
    cfg = load_scene("sphere", rows=res, cols=res)
    # The shipped self-contact radius (0.1) is 0.4 of the 25 x 25 grid's spacing; keep that
    # ratio, else at 96 x 96 every neighbouring pair starts in self-contact.
    cfg["self_collision"]["radius"] *= 24 / (res - 1)
    sim = Simulator.from_config(cfg)
    x = sim.positions
    top = 2.0 + cfg["contact"]["thickness"] + 0.03
    x = x + np.array([0.0, top - x[:, 1].min(), 0.0])
    speed = np.sqrt(2 * 9.81 * (cfg["placement"]["translate"][1] - top))
    v = np.zeros_like(x)
    v[:, 1] = -speed
    return Case(f"sphere{res}x{res}", cfg, steps, x, v)


def cases(names: Sequence[str], quick: bool) -> list:
    """Makers of the named cases (built one at a time: the large spheres take memory)."""
    short = 20 if quick else None
    makers = {
        "hat": lambda: hat_case(short or 400),
        "sock": lambda: sock_case(short or 400),
        "wind24x24": lambda: Case("wind24x24", load_scene("wind", rows=24, cols=24), short or 100),
        "sphere24x24": lambda: sphere_case(24, short or 150),
        "sphere48x48": lambda: sphere_case(48, short or 100),
        "sphere96x96": lambda: sphere_case(96, short or 50),
    }
    return [makers[n] for n in names]


def rollout(case: Case, settings: dict) -> tuple[Simulator, dict, float]:
    """Recorded rollout; returns the simulator (tape kept), its profile (with
    ``pushing_steps``: steps ending with a contact that pushes) and the unconverged share."""
    sim = Simulator.from_config(case.cfg)
    sim.set_solver(parallel=False, **settings)
    sim.reset(x=case.x0, v=case.v0)
    sim.set_recording(True)
    sim.reset_profile()
    pushing = 0
    for k in range(case.steps):
        sim.step(attachment_targets=None if case.targets is None else case.targets[k])
        c = sim.last_step()["contacts"]
        pushing += c["stick"] + c["slip"] > 0
    prof = sim.profile()
    prof["pushing_steps"] = pushing
    return sim, prof, prof["unconverged_steps"] / case.steps


def gradient(sim: Simulator, weights: np.ndarray, solver: str | None) -> tuple[np.ndarray, dict, float]:
    t = time.perf_counter()
    g = sim.backward(dl_dx=weights, solver=solver)
    wall = time.perf_counter() - t
    flat = np.concatenate([g["x0"].ravel(), g["v0"].ravel(), g["attachment_targets"].ravel()])
    return flat, g, wall


def measure(case: Case, label: str, settings_names: Sequence[str]) -> list[dict]:
    t = time.perf_counter()
    ref_sim, ref_prof, ref_unconv = rollout(case, REFERENCE_SETTINGS)
    print(f"{case.name} reference: {time.perf_counter() - t:.1f} s, {ref_prof['iterations'] / case.steps:.0f} it/step, "
          f"{100 * ref_unconv:.0f} % unconverged", flush=True)
    n = ref_sim.num_nodes
    weights = np.random.default_rng(1).normal(0, 1, (case.steps, n, 3)) / n
    g_ref, _, _ = gradient(ref_sim, weights, "direct")
    scale = np.abs(g_ref).max()
    rows = []
    for name in settings_names:
        settings = SETTINGS[name]
        if name == "semismooth" and case.cfg["solver"]["polish"] == "semismooth":
            continue  # the env's own setting already
        sim, prof, unconv = rollout(case, settings)
        g, out, wall = gradient(sim, weights, None)
        steps = case.steps
        rows.append({
            "label": label,
            "scene": case.name,
            "nodes": n,
            "steps": steps,
            "setting": name,
            "polish": sim.solver()["polish"],
            "fwd_ms": 1e3 * prof["total_s"] / steps,
            "pd_iters": prof["iterations"] / steps,
            "newton_steps": prof["newton_steps"] / steps,
            "newton_ms": 1e3 * prof["newton_s"] / steps,
            "contact_steps_pct": 100 * prof["pushing_steps"] / steps,
            "contact_ms": 1e3 * (prof["contact_s"] + prof["detection_s"]) / steps,
            "unconverged_pct": 100 * unconv,
            "bwd_ms": 1e3 * wall / steps,
            "adjoint_iters": float(np.mean(out["iterations"])),
            "factored_pct": 100 * float(np.mean(out["factored"])),
            "fell_back_pct": 100 * float(np.mean(out["fell_back"])),
            "total_ms": 1e3 * prof["total_s"] / steps + 1e3 * wall / steps,
            "grad_err": float(np.abs(g - g_ref).max() / scale),
            "grad_rel_l2": float(np.linalg.norm(g - g_ref) / np.linalg.norm(g_ref)),
            "warnings": len(out["warnings"]),
            "ref_fwd_ms": 1e3 * ref_prof["total_s"] / steps,
            "ref_pd_iters": ref_prof["iterations"] / steps,
            "ref_unconverged_pct": 100 * ref_unconv,
        })
        r = rows[-1]
        print(f"{case.name} {name}: fwd {r['fwd_ms']:.2f} ms ({r['pd_iters']:.1f} it), bwd {r['bwd_ms']:.2f} ms "
              f"({r['adjoint_iters']:.1f} it), grad_err {r['grad_err']:.2e}", flush=True)
    return rows


ALL_SCENES = ["hat", "sock", "wind24x24", "sphere24x24", "sphere48x48", "sphere96x96"]


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--label", default="current", help="tag of this run's rows (e.g. before / after)")
    p.add_argument("--scenes", nargs="*", default=ALL_SCENES, choices=ALL_SCENES)
    p.add_argument("--settings", nargs="*", default=list(SETTINGS), choices=list(SETTINGS))
    p.add_argument("--quick", action="store_true", help="20 steps per scene")
    p.add_argument("--out", default=None)
    p.add_argument("--note", default="", help="what this run measures (kept with its rows: the build, the machine's load)")
    args = p.parse_args(argv)
    notes = (__doc__.split("\n\n", 1)[1].split("Writes")[0].strip().replace("\n", " ")
             + " Target (issue 15): Hat forward + backward <= 5 ms/step at grad_err <= 1e-3.")
    new = []
    run = results_io.meta({"label": args.label, "scenes": args.scenes, "note": args.note})
    for make in cases(args.scenes, args.quick):
        new += measure(make(), args.label, args.settings)
        # Written after every scene: a long run stopped early keeps what it measured.
        out = results_io.write_merged("gradient_cost", new, lambda r: (r.get("label"), r.get("scene")),
                                      run, "Gradient cost per step", notes, out_dir=args.out)
    print(results_io.markdown_table(new))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
