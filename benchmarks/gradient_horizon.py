"""Gradient horizon: over how many contact-rich steps a gradient still says something.

``gradient_cost`` found the sphere drops' gradients at 48 and 96 nodes a side far from their
1e-13 reference under every solver setting (grad_err 0.26-1.4). This study asks whether the
gradient or the reference is wrong, per scene and horizon:

- ``grad_max``: the largest entry of d loss / d(x0, v0) from a 1e-13 rollout (direct backward);
  the loss is random linear weights on every step's positions, as in ``gradient_cost``;
- ``repro_err``: the same gradient from a 1e-12 rollout against it, max |g12 - g13| / max |g13|:
  how much a 1e-13 perturbation of the trajectory moves the gradient (a reference only where
  this is small);
- ``fd_1e-6`` / ``fd_1e-4``: central differences of the loss (forward at 1e-13) along one random
  direction in v0 with those steps (m/s), against the analytic directional derivative
  ``analytic``; ``fd_err_*`` = |fd - analytic| / |analytic|. Small at 1e-6 means the gradient is
  the loss's exact local derivative; small at 1e-4 too means it also predicts the loss over
  perturbations of that size (what an optimizer's step needs).

Scenes: the sphere drops of ``gradient_cost`` at 24 and 48 nodes a side, its ``hat`` (carried
onto the head by its effectors) and its ``sock`` (Sock-v0's scene, its four effectors dragging
it from TEST_STARTS[0] onto the foot over 400 steps; the first push on the foot at step ~120). Variants: ``full`` (the scene as shipped), ``mu0`` (frictionless obstacles), ``noself``
(without self-collision). Solver: the gradient preset (Anderson), cap 20000, with ``--polish``
(default none; ``env``: the scene's own, Hat-v0's semismooth). Without a polish the Hat is not
smooth from 50 steps on: at step 35 of one rollout Anderson-PD stops (update below 1e-13) 1e-3
from where a neighbouring rollout's step ends, and the next step takes 1000 iterations to get
back; with the Newton polish (which leaves saddles along negative curvature) both stay within
1e-6.
Writes benchmarks/results/gradient_horizon.{json,md}; a run replaces only the rows it measures
(same scene, variant and horizon), so the header names the last run's command.

Run: .venv/bin/python -m benchmarks gradient_horizon [--scenes sphere48x48 ...] [--horizons 10 25 50 100]
     [--variants full mu0] [--out DIR]
"""

from __future__ import annotations

import argparse
import copy
import time
from typing import Sequence

import numpy as np

from benchmarks import results_io
from benchmarks.gradient_cost import Case, gradient, hat_case, rollout, sock_case, sphere_case
from diffcloth_gym import Simulator

SOLVER = dict(preset="gradient", max_iterations=20000, record_max_iterations=20000)
#: ``env``: each scene's own polish (Hat-v0's semismooth; newton for the spheres).
POLISHES = ("none", "newton", "semismooth", "env")
SCENES = {"sphere24x24": 24, "sphere48x48": 48, "hat": None, "sock": None}
VARIANTS = ("full", "mu0", "noself")


def variant_case(scene: str, variant: str, steps: int) -> Case:
    makers = {"hat": hat_case, "sock": sock_case}
    case = makers[scene](steps) if scene in makers else sphere_case(SCENES[scene], steps)
    cfg = copy.deepcopy(case.cfg)
    if variant == "mu0":
        for obstacle in cfg["obstacles"]:
            obstacle["mu"] = 0.0
    elif variant == "noself":
        cfg["effects"] = [e for e in cfg["effects"] if e != "self_collision"]
        cfg.pop("self_collision", None)
    case.cfg = cfg
    return case


def settings(case: Case, tol: float, polish: str) -> dict:
    polish = case.cfg["solver"]["polish"] if polish == "env" else polish
    return {**SOLVER, "tolerance": tol, "record_tolerance": tol, "polish": polish}


def loss_of(case: Case, weights: np.ndarray, v0: np.ndarray, polish: str) -> float:
    """The loss of an unrecorded 1e-13 rollout from (x0, v0)."""
    sim = Simulator.from_config(case.cfg)
    sim.set_solver(parallel=False, **settings(case, 1e-13, polish))
    sim.reset(x=case.x0, v=v0)
    loss = 0.0
    for k in range(case.steps):
        sim.step(attachment_targets=None if case.targets is None else case.targets[k])
        loss += float(np.sum(weights[k] * sim.positions))
    return loss


def measure(scene: str, variant: str, steps: int, polish: str = "none") -> dict:
    t = time.perf_counter()
    case = variant_case(scene, variant, steps)
    grads, pushing = {}, 0
    for tol in (1e-12, 1e-13):
        sim, prof, _ = rollout(case, settings(case, tol, polish))
        n = sim.num_nodes
        weights = np.random.default_rng(1).normal(0, 1, (steps, n, 3)) / n
        grads[tol], _, _ = gradient(sim, weights, "direct")
        pushing = prof["pushing_steps"]
    g = grads[1e-13]
    m = 3 * n
    direction = np.random.default_rng(7).normal(0, 1, case.v0.shape)
    analytic = float(g[m:2 * m] @ direction.ravel())
    row = {"scene": scene, "variant": variant, "polish": settings(case, 0.0, polish)["polish"], "steps": steps,
           "pushing_steps": pushing,
           "grad_max": float(np.abs(g).max()),
           "repro_err": float(np.abs(grads[1e-12] - g).max() / np.abs(g).max()),
           "analytic": analytic}
    for eps in (1e-6, 1e-4):
        fd = (loss_of(case, weights, case.v0 + eps * direction, polish)
              - loss_of(case, weights, case.v0 - eps * direction, polish)) / (2 * eps)
        row[f"fd_{eps:g}"] = fd
        row[f"fd_err_{eps:g}"] = abs(fd - analytic) / abs(analytic)
    row["wall_s"] = time.perf_counter() - t
    print(" ".join(f"{k}={v:.3g}" if isinstance(v, float) else f"{k}={v}" for k, v in row.items()), flush=True)
    return row


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenes", nargs="*", default=["sphere48x48"], choices=list(SCENES))
    p.add_argument("--horizons", nargs="*", type=int, default=[10, 25, 50, 100])
    p.add_argument("--variants", nargs="*", default=list(VARIANTS), choices=list(VARIANTS))
    p.add_argument("--polish", default="none", choices=POLISHES)
    p.add_argument("--out", default=None)
    p.add_argument("--note", default="", help="what this run measures (kept with its rows: the build, the machine's load)")
    args = p.parse_args(argv)
    notes = __doc__.split("\n\n", 1)[1].split("Writes")[0].strip().replace("\n", " ")
    rows = []
    run = results_io.meta({"scenes": args.scenes, "horizons": args.horizons, "note": args.note})
    key = lambda r: (r.get("scene"), r.get("variant"), r.get("polish"), r.get("steps"))
    for scene in args.scenes:
        for variant in args.variants:
            for steps in args.horizons:
                rows.append(measure(scene, variant, steps, args.polish))
                # Rows of earlier runs (other scenes, variants or horizons) are kept.
                out = results_io.write_merged("gradient_horizon", rows, key, run, "Gradient horizon", notes,
                                              out_dir=args.out)
    print(results_io.markdown_table(rows))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
