"""The paper's Fig. 4 on our simulator: per-node constant forces fly a napkin along a reference
motion (``diffcloth_gym.optim.flying_napkin``); L-BFGS-B (with our adjoint gradients), CMA-ES
and (1+1)-ES from the same seeded starts under the same step budget, at 4x4, 5x5, 7x7 and 10x10
nodes (48, 75, 147, 300 variables).

Reported per resolution and method: the min-over-seeds envelope of the best loss against
simulated steps (the paper plots the minimum over its five seeds), and the speedup of L-BFGS-B:
the steps an ES needs to bring its envelope to a loss level over the steps L-BFGS-B needs. Two
levels: the paper's absolute 0.01, and the common level (the lowest loss every method reached
within the budget, so the ratio is always measured, never extrapolated). Steps are counted as
the paper counts them (an evaluation with a gradient costs forward plus backward steps: see
``diffcloth_gym.optim.objective``).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from benchmarks import results_io
from diffcloth_gym.optim import DRIVERS, flying_napkin, initial_guess, write_csv

RESOLUTIONS = (4, 5, 7, 10)
PAPER_LEVEL = 0.01


def envelope(runs, grid: np.ndarray) -> np.ndarray:
    """Min over runs of each run's best loss after ``grid`` steps (inf before its first)."""
    out = np.full(len(grid), np.inf)
    for r in runs:
        steps = np.array([h["steps"] for h in r.history])
        best = np.array([h["best"] for h in r.history])
        idx = np.searchsorted(steps, grid, side="right") - 1
        vals = np.where(idx >= 0, best[np.clip(idx, 0, None)], np.inf)
        out = np.minimum(out, vals)
    return out


def steps_to(runs, level: float) -> int | None:
    """Fewest steps any seed needed to reach ``level`` (the envelope's crossing)."""
    hits = [s for s in (r.steps_to(level) for r in runs) if s is not None]
    return min(hits) if hits else None


def study(resolutions, seeds, budget: int, steps: int, spread: float, progress: bool):
    runs, rows = [], []
    for res in resolutions:
        task = flying_napkin(res, steps=steps)
        obj = task.objective()
        per_method = {}
        for method, driver in DRIVERS.items():
            per_method[method] = []
            for seed in seeds:
                u0 = initial_guess(task.param, seed, spread)
                run = driver(obj, u0, budget, seed=seed, show_progress=progress)
                run.task = task.name
                per_method[method].append(run)
                runs.append((task.name, task.param.size, run))
                print(f"{task.name} {method:9s} seed {seed}: loss {run.initial_loss:.3g} -> {run.best_loss:.3g} "
                      f"in {run.steps_used} steps ({run.evaluations} evaluations, {run.seconds:.0f} s; {run.stop})",
                      flush=True)
        common = max(min(r.best_loss for r in rs) for rs in per_method.values())
        lb = per_method["L-BFGS-B"]
        for level_name, level in (("paper 0.01", PAPER_LEVEL), ("common", common)):
            s_lb = steps_to(lb, level)
            for method in ("CMA-ES", "(1+1)-ES"):
                s_es = steps_to(per_method[method], level)
                rows.append({
                    "task": task.name, "dof": task.param.size, "level": level_name, "loss_level": level,
                    "method": method, "lbfgsb_steps": s_lb, "es_steps": s_es,
                    # An ES that never reached the level: the speedup is at least budget / L-BFGS-B steps.
                    "speedup": (s_es / s_lb) if (s_lb and s_es) else None,
                    "speedup_at_least": (budget / s_lb) if (s_lb and not s_es) else None,
                })
    return runs, rows


def plot(runs, rows, budget: int, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tasks = list(dict.fromkeys(t for t, _, _ in runs))
    fig, axes = plt.subplots(1, len(tasks) + 1, figsize=(4.2 * (len(tasks) + 1), 3.6))
    grid = np.linspace(0, budget, 400)
    colors = {"L-BFGS-B": "C0", "CMA-ES": "C1", "(1+1)-ES": "C2"}
    for ax, task in zip(axes, tasks):
        dof = next(d for t, d, _ in runs if t == task)
        for method, c in colors.items():
            rs = [r for t, _, r in runs if t == task and r.method == method]
            ax.plot(grid, envelope(rs, grid), color=c, label=method)
        ax.axhline(PAPER_LEVEL, color="gray", lw=0.6, ls=":")
        ax.set(yscale="log", xlabel="simulated steps (forward + backward)", title=f"{task} ({dof} DoF)")
    axes[0].set_ylabel("loss (min over seeds)")
    axes[0].legend(fontsize=8)
    ax = axes[-1]
    for method, c in (("CMA-ES", "C1"), ("(1+1)-ES", "C2")):
        for level, ls in (("common", "-"), ("paper 0.01", "--")):
            rs = [r for r in rows if r["method"] == method and r["level"] == level]
            x = [r["dof"] for r in rs]
            y = [r["speedup"] if r["speedup"] is not None else r["speedup_at_least"] for r in rs]
            ok = [(a, b) for a, b in zip(x, y) if b is not None]
            if ok:
                ax.plot(*zip(*ok), ls, marker="o", color=c, label=f"vs {method} ({level})")
    ax.set(xlabel="DoF", ylabel="speedup of L-BFGS-B (ES steps / L-BFGS-B steps)", yscale="log",
           title="speedup to a loss level")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def markdown(meta: dict, summary: list[dict], rows: list[dict]) -> str:
    t = results_io.markdown_table
    return "\n".join([
        "# Open-loop optimization: the flying napkin (paper Fig. 4)", "",
        f"`{meta['command']}` — {meta['date']}, {meta['cpu']}, git {meta['git']}, {meta['minutes']:.1f} min", "",
        __doc__.strip().split("\n\n")[0].replace("\n", " "), "",
        f"Setting: {meta['steps']}-step rollouts (h = 0.01 s), solver preset `gradient` for every evaluation; "
        f"budget {meta['budget']} simulated steps per run; seeds {meta['seeds']} (the same starts for every method: "
        f"uniform in the middle {meta['spread']:.0%} of the force box [-10, 10] mean-node weights); "
        "L-BFGS-B's objective scaled so its first step moves each force by at most 10 % of its range; CMA-ES sigma0 "
        "0.25 of the range, default population 4 + 3 ln d; (1+1)-ES sigma0 0.25 with the 1/5th rule. "
        f"{'The full budget.' if meta['full'] else 'A reduced budget (the full one is --budget 50000 --seeds 0 1 2 3 4).'}",
        "", "![fig4](openloop_fig4.png)", "",
        "## Per run (best loss over the budget)", "", t(summary), "",
        "## Speedup of L-BFGS-B to a loss level", "",
        "`es_steps` / `lbfgsb_steps`: steps the fastest seed needed to reach the level; `speedup_at_least`: the ES "
        "never reached it within the budget, so the speedup is at least budget / L-BFGS-B steps.", "",
        t(rows), "",
        "Why our numbers differ from the paper's: its target motion, horizon and force units are not in its public "
        "code (ours: a known smooth force field, 50 steps, forces in mean-node weights); our step count for "
        "L-BFGS-B includes its backward steps, as its text says. Per-evaluation log: `out/openloop_fig4.csv` (not "
        "committed; `openloop.json` keeps each run's improvements).", ""])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks openloop fig4", description=__doc__.split("\n\n")[0])
    ap.add_argument("--resolutions", type=int, nargs="+", default=list(RESOLUTIONS))
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--budget", type=int, default=20000, help="simulated steps per run (default 20000)")
    ap.add_argument("--steps", type=int, default=50, help="rollout length (default 50)")
    ap.add_argument("--spread", type=float, default=0.5, help="start spread, fraction of the force box (default 0.5)")
    ap.add_argument("--out", type=Path, default=results_io.RESULTS_DIR)
    ap.add_argument("--log", type=Path, default=Path("out/openloop_fig4.csv"),
                    help="per-evaluation CSV log (default out/openloop_fig4.csv, not committed)")
    ap.add_argument("--no-progress", action="store_true")
    args = ap.parse_args(argv)
    t0 = time.time()
    runs, rows = study(args.resolutions, args.seeds, args.budget, args.steps, args.spread, not args.no_progress)
    full = args.budget >= 50000 and len(args.seeds) >= 5
    meta = results_io.meta({"budget": args.budget, "seeds": args.seeds, "steps": args.steps, "spread": args.spread,
                            "full": full, "minutes": (time.time() - t0) / 60})
    summary = [{"task": t, "dof": d, "method": r.method, "seed": r.seed, "initial_loss": r.initial_loss,
                "best_loss": r.best_loss, "steps_used": r.steps_used, "evaluations": r.evaluations,
                "seconds": r.seconds, "unconverged_steps": r.unconverged_steps, "stop": r.stop} for t, d, r in runs]
    args.out.mkdir(parents=True, exist_ok=True)
    plot(runs, rows, args.budget, args.out / "openloop_fig4.png")
    # The per-evaluation log (every evaluation of every run: megabytes) goes beside the
    # results, uncommitted; the JSON keeps each run's improvements (steps, best loss).
    args.log.parent.mkdir(parents=True, exist_ok=True)
    write_csv([r for _, _, r in runs], args.log)
    import json

    def compact(r):
        d = r.to_dict()
        d["improvements"] = [[h["steps"], h["best"]] for i, h in enumerate(r.history)
                             if i == 0 or h["best"] < r.history[i - 1]["best"]]
        del d["history"]
        return d

    # Other studies' keys (the table's) stay.
    path = args.out / "openloop.json"
    data = json.loads(path.read_text()) if path.exists() else {}
    data.update(meta=meta, fig4={"summary": summary, "speedup": rows,
                                 "runs": [dict(compact(r), task=t, dof=d) for t, d, r in runs]})
    path.write_text(json.dumps(data, separators=(",", ":")))
    (args.out / "openloop.md").write_text(markdown(meta, summary, rows))
    print(f"wrote {args.out / 'openloop.md'}")
    return 0
