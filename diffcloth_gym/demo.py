"""The main job: the hat controller comparison (paper Sec. 6.5) on a short budget. Trains the
paper's controller with analytic policy gradients (APG) through the simulator and with PPO
(stable-baselines3) on ``DiffCloth/Hat-v0``, evaluates both on the env's fixed test starts,
prints a table and writes a plot of test loss vs simulated time steps and a GIF of the APG
policy (about 5 minutes on a quiet 2-core machine, at most 10).

Run with ``scripts/demo`` (or ``python -m diffcloth_gym.demo``). The full-budget comparison
is ``python scripts/compare_hat.py --budget full`` (see the README).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--budget", default="budget_demo", help="training budget config (name or TOML path)")
    parser.add_argument("--out", default="out/demo", help="folder for the table, plot and GIF")
    parser.add_argument("--fresh", action="store_true", help="start over instead of resuming earlier runs")
    args = parser.parse_args(argv)

    from diffcloth_gym.training import compare

    t0 = time.perf_counter()
    r = compare.run(args.budget, out=args.out, runs=Path(args.out) / "runs", resume=not args.fresh,
                    command="scripts/demo" + (f" --budget {args.budget}" if args.budget != "budget_demo" else ""))
    print()
    print(f"{r['env_id']}: APG vs PPO ({r['budget']} budget; test loss on {len(r['test_starts'])} test starts)")
    print(f"{'method':<6} {'seed':>4} {'test loss':>10} {'success':>8} {'time steps':>11} {'paper count':>11} "
          f"{'train s':>8}")
    for s in r["runs"]:
        print(f"{s['method'].upper():<6} {s['seed']:>4} {s['final_test_loss']:>10.4g} {s['success_rate']:>8.0%} "
              f"{s['forward']:>11,} {s['paper_steps']:>11,} {s['train_s']:>8.0f}")
    print(f"\ntotal {time.perf_counter() - t0:.0f} s; results: {args.out}/hat_controller.md, plot: "
          f"{args.out}/hat_controller.png" + (f", GIF: {r['gif']}" if r.get("gif") else ""))
    return r


if __name__ == "__main__":
    main()
