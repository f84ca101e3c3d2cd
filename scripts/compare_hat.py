"""The hat controller comparison (APG vs PPO) under one budget config; thin entry point over
``diffcloth_gym.training.compare``.

    .venv/bin/python scripts/compare_hat.py --budget full   # benchmarks/results/hat_controller.*
    .venv/bin/python scripts/compare_hat.py --budget demo --out out/demo

Runs checkpoint every APG/SHAC epoch and PPO rollout; the same command resumes them. The full
budget's run folders live in benchmarks/results/hat_controller_runs/ and are committed: a
session runs a part with --max-minutes M, then commits them with the results.
"""

import argparse
import shlex
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

# The full run takes days: its checkpoints and logs are committed beside its results, so that
# each session continues where the last one stopped (a new session's work tree has no out/).
FULL_RUNS = "benchmarks/results/hat_controller_runs"


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--budget", default="full", help="demo | full | a budget TOML path (default full)")
    p.add_argument("--out", default=None, help="results folder (default benchmarks/results for full, else out/<budget>)")
    p.add_argument("--runs", default=None, help="run folders with checkpoints and logs (default: for the full budget "
                   f"{FULL_RUNS}, committed so that later sessions resume it; else out/runs/<budget>)")
    p.add_argument("--seeds", type=int, nargs="*", default=None, help="override the budget's seeds")
    p.add_argument("--methods", nargs="*", default=None, help="override the budget's methods (apg ppo)")
    p.add_argument("--max-minutes", type=float, default=None, help="stop training after this long (checkpointed; "
                   "the results say partial; rerun to resume)")
    p.add_argument("--fresh", action="store_true", help="ignore existing checkpoints")
    p.add_argument("--no-gif", action="store_true")
    p.add_argument("--via", default=None, help="the command line the user ran, when a wrapper runs this file (e.g. "
                   "'scripts/hat_full_run --max-minutes 60', which runs the comparison's pinned build): the results "
                   "name it, and its program as the resume command")
    args = p.parse_args(argv)
    from diffcloth_gym.training import compare

    budget = args.budget if args.budget.endswith(".toml") else f"budget_{args.budget}"
    tag = Path(budget).stem.removeprefix("budget_")
    out = args.out or ("benchmarks/results" if tag == "full" else f"out/{tag}")
    runs = args.runs or (FULL_RUNS if tag == "full" else f"out/runs/{tag}")
    command = "python scripts/compare_hat.py " + " ".join(shlex.quote(a) for a in (argv or sys.argv[1:]))
    resume = f"python scripts/compare_hat.py --budget {shlex.quote(args.budget)}"
    if args.runs:
        resume += f" --runs {shlex.quote(args.runs)}"
    if args.via:
        command, resume = args.via, shlex.split(args.via)[0]
    return compare.run(budget, out=out, runs=runs, seeds=args.seeds, methods=args.methods,
                       max_minutes=args.max_minutes, resume=not args.fresh, gif=not args.no_gif, command=command.strip(),
                       resume_command=resume + " [--max-minutes M]")


if __name__ == "__main__":
    main()
