"""Where a Hat-v0 forward step's time goes under the actions the harness really sends (issue 15:
the full comparison's duration is set by these steps, not by a scripted motion).

Workloads, each from the first ``--starts`` of Hat-v0's TEST_STARTS, one member per start, one
thread, plain (unrecorded) env steps at the env's own settings:

- ``apg``: the APG policy of a saved run (default: the complete second attempt's seed 0,
  ``hat_controller_runs_v2/apg_seed0``), deterministic: what APG's rollouts and every
  evaluation simulate;
- ``ppo``: a PPO policy of a saved run (default: ``hat_controller_runs_v2/ppo_seed0``, 160,000
  steps into training), sampling its Gaussian as PPO's rollouts do (seeded): most of the
  comparison's time steps are these;
- ``random``: uniform random actions in the action box (seeded).

Per workload: ms per step inside Rust (the members' profile totals over the steps), PD
iterations, trust-region Newton steps and their CG iterations, contact Newton steps per step,
the share of the time spent in the polish (``newton_s``), and the slow steps: those above
``--slow`` PD iterations (their share of the steps, of the iterations and of the time; each
step's time is the member's profile difference over that step). The saved policies were
trained on earlier builds; here they only generate actions, so a build change cannot make
them stale. Iteration counts are exact; times are CPU-bound but the machine is shared: compare
rows of one run.

Writes benchmarks/results/hat_workloads.{json,md} (rows labelled by ``--label``; a run
replaces only its own label's rows).
Run: .venv/bin/python -m benchmarks hat_workloads [--label L] [--workloads apg ppo random]
     [--starts 4] [--steps 400] [--note TEXT]
"""

from __future__ import annotations

import argparse
import io
import time
from pathlib import Path
from typing import Callable, Sequence

import gymnasium as gym
import numpy as np
import torch

import diffcloth_gym  # noqa: F401  (registers the envs)
from benchmarks import results_io
from diffcloth_gym.training.accounting import engine_of
from diffcloth_gym.training.evaluate import as_policy, test_starts

ENV_ID = "DiffCloth/Hat-v0"
RUNS = results_io.RESULTS_DIR / "hat_controller_runs_v2"
WORKLOADS = ("apg", "ppo", "random")


def apg_actions(checkpoint: Path) -> Callable[[np.ndarray], np.ndarray]:
    from diffcloth_gym.training.policy import MLPPolicy

    ck = torch.load(checkpoint, weights_only=False)
    policy = MLPPolicy(**ck["policy_config"])
    policy.load_state_dict(ck["policy"])
    return as_policy(policy)


def ppo_actions(checkpoint: Path, seed: int) -> Callable[[np.ndarray], np.ndarray]:
    from stable_baselines3 import PPO

    model = PPO.load(io.BytesIO(torch.load(checkpoint, weights_only=False)["model"]), device="cpu")
    model.set_random_seed(seed)
    return lambda obs: model.predict(obs.astype(np.float32), deterministic=False)[0].astype(np.float64)


def random_actions(space: gym.spaces.Box, members: int, seed: int) -> Callable[[np.ndarray], np.ndarray]:
    rng = np.random.default_rng(seed)
    return lambda obs: rng.uniform(space.low, space.high, size=(members, *space.shape))


def measure(workload: str, act: Callable[[np.ndarray], np.ndarray], env, starts: list, steps: int,
            slow: int) -> dict:
    engine = engine_of(env)
    members = len(starts)
    obs, _ = env.reset(options={"starts": starts})
    before = [engine.batch.profile(i) for i in range(members)]
    last = [p["total_s"] for p in before]
    step_iterations, step_seconds = [], []
    wall = time.perf_counter()
    for _ in range(steps):
        obs, _, _, truncated, info = env.step(act(obs))
        now = [engine.batch.profile(i)["total_s"] for i in range(members)]
        step_iterations += [int(k) for k in info["solver_iterations"]]
        step_seconds += [b - a for a, b in zip(last, now)]
        last = now
        if truncated.all():
            break
    wall = time.perf_counter() - wall
    after = [engine.batch.profile(i) for i in range(members)]
    total = {k: sum(a[k] - b[k] for a, b in zip(after, before)) for k in after[0]}
    n = len(step_iterations)
    iterations, seconds = np.array(step_iterations), np.array(step_seconds)
    # Two counts of one thing (the profile's and the steps' own): the accounting is exact.
    if int(total["iterations"]) != int(iterations.sum()):
        raise RuntimeError(f"profile counts {total['iterations']} PD iterations, the steps {iterations.sum()}")
    is_slow = iterations > slow
    per = lambda key: total[key] / n  # noqa: E731
    return {
        "workload": workload, "members": members, "steps": n,
        "ms_per_step": 1e3 * total["total_s"] / n, "wall_ms_per_step": 1e3 * wall / n,
        "pd_iters": per("iterations"), "p90_iters": float(np.percentile(iterations, 90)),
        "newton_steps": per("newton_steps"), "newton_cg_iters": per("newton_cg_iterations"),
        "contact_newton_steps": per("contact_newton_steps"),
        "polish_time_pct": 100 * total["newton_s"] / total["total_s"],
        "slow_steps_pct": 100 * float(is_slow.mean()),
        "slow_iters_pct": 100 * float(iterations[is_slow].sum() / max(iterations.sum(), 1)),
        "slow_time_pct": 100 * float(seconds[is_slow].sum() / max(seconds.sum(), 1e-300)),
        "unconverged": int(total["unconverged_steps"]),
    }


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--label", default="current")
    p.add_argument("--workloads", nargs="*", default=list(WORKLOADS), choices=WORKLOADS)
    p.add_argument("--starts", type=int, default=4, help="the first N of TEST_STARTS")
    p.add_argument("--steps", type=int, default=400)
    p.add_argument("--slow", type=int, default=500, help="PD iterations above which a step counts as slow")
    p.add_argument("--apg", type=Path, default=RUNS / "apg_seed0" / "checkpoint.pt")
    p.add_argument("--ppo", type=Path, default=RUNS / "ppo_seed0" / "checkpoint.pt")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--note", default="")
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)
    starts = list(test_starts(ENV_ID))[: args.starts]
    env = gym.make_vec(ENV_ID, num_envs=len(starts), threads=1)
    makers = {
        "apg": lambda: apg_actions(args.apg),
        "ppo": lambda: ppo_actions(args.ppo, args.seed),
        "random": lambda: random_actions(env.single_action_space, len(starts), args.seed),
    }
    notes = __doc__.split("\n\n", 1)[1].split("Writes")[0].strip().replace("\n", " ")
    run = results_io.meta({"label": args.label, "workloads": args.workloads, "note": args.note})
    rows = []
    for workload in args.workloads:
        row = measure(workload, makers[workload](), env, starts, args.steps, args.slow)
        rows.append({"label": args.label, **row})
        out = results_io.write_merged("hat_workloads", rows, lambda r: (r.get("label"), r.get("workload")),
                                      run, "Hat-v0 forward time per workload", notes, out_dir=args.out)
        print(results_io.markdown_table(rows[-1:]))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
