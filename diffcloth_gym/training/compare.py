"""The comparison: every method and seed of a budget config, trained (or resumed) in its own
run folder and evaluated on the same test starts with the same env settings; then the results
as JSON, a Markdown table, a plot of test loss vs time steps, and a GIF of the APG policy.

Per run it reports the final test loss and success rate, time steps (ours, counted, and the
paper's way), backward steps, the time steps (both counts) at which the test loss first reached
1.1 x APG's final test loss (mean over APG seeds; ``null``: not reached within the budget), and
wall-clock seconds of training and evaluation; PPO over APG's steps to that loss in both counts
(the paper's 85x is in its count), with the evaluation interval that bounds their resolution.
"""

from __future__ import annotations

import json
import platform
import subprocess
import time
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from diffcloth_gym.training.accounting import threads
from diffcloth_gym.training.config import load, method_config
from diffcloth_gym.training.evaluate import test_starts

METHODS = ("apg", "ppo", "shac")
COLORS = {"apg": "tab:blue", "ppo": "tab:orange", "shac": "tab:green"}


def eval_starts(budget: Mapping[str, Any]) -> list:
    """The budget's test starts: every ``TEST_STARTS`` (``eval_stride = 1``) or every k-th."""
    return list(test_starts(budget["env_id"]))[::int(budget.get("eval_stride", 1))]


def trainer_for(method: str, budget: Mapping[str, Any], run_dir: Path, seed: int, progress: bool, resume: bool):
    cfg = method_config(method, budget)
    starts = eval_starts(budget)
    if method == "apg":
        from diffcloth_gym.training.apg import APGTrainer

        return APGTrainer(cfg, run_dir, seed, resume=resume, progress=progress, eval_starts=starts)
    if method == "ppo":
        from diffcloth_gym.training.ppo import PPOTrainer

        return PPOTrainer(cfg, run_dir, seed, resume=resume, progress=progress, eval_starts=starts)
    if method == "shac":
        from diffcloth_gym.training.shac import SHACTrainer

        return SHACTrainer(cfg, run_dir, seed, resume=resume, progress=progress, eval_starts=starts)
    raise ValueError(f"unknown method {method!r}; known: {METHODS}")


def steps_to_reach(curve: Sequence[Mapping[str, Any]], target: float | None) -> dict[str, Any] | None:
    """The first evaluation at or below ``target``: its counted and paper steps."""
    if target is None:
        return None
    for p in curve:
        if p["test_loss"] <= target:
            return {"steps": p["steps"], "paper_steps": p["paper_steps"]}
    return None


def run(budget: str | Mapping[str, Any] = "budget_demo", out: str | Path = "out/demo",
        runs: str | Path | None = None, seeds: Sequence[int] | None = None, methods: Sequence[str] | None = None,
        max_minutes: float | None = None, resume: bool = True, progress: bool = True, gif: bool = True,
        name: str = "hat_controller", command: str | None = None,
        resume_command: str | None = None) -> dict[str, Any]:
    """Runs (or resumes) every method and seed of ``budget``; writes ``out/name.{json,md,png}``
    and ``out/name.gif``. ``max_minutes`` stops training (after a checkpoint) when the time is
    up; the results then say ``partial`` and the same command resumes."""
    budget_name = budget if isinstance(budget, str) else budget.get("name", "custom")
    budget = load(budget) if isinstance(budget, str) else dict(budget)
    seeds = list(budget["seeds"] if seeds is None else seeds)
    methods = list(budget["methods"] if methods is None else methods)
    out = Path(out)
    runs = Path(runs) if runs is not None else out / "runs"
    deadline = None if max_minutes is None else time.time() + 60 * max_minutes
    t0 = time.perf_counter()
    summaries, gif_frames, gif_engine = [], None, None
    for seed in seeds:
        for method in methods:
            trainer = trainer_for(method, budget, runs / f"{method}_seed{seed}", seed, progress, resume)
            trainer.train(deadline=deadline)
            summaries.append(trainer.summary())
            if gif and method == "apg" and gif_frames is None:
                stride = int(budget.get("gif_starts_stride", 5))
                starts = list(test_starts(budget["env_id"]))[::stride][:4]
                from diffcloth_gym.training.evaluate import evaluate

                ev = evaluate(trainer.policy, budget["env_id"], starts, trainer.cfg["env"],
                              frames_every=int(budget.get("gif_frame_every", 10)))
                gif_frames, gif_engine = ev.frames, trainer.engine
    results = summarize(budget, budget_name, summaries, seeds, methods)
    results["wall_s"] = time.perf_counter() - t0
    results["command"] = command
    results["resume_command"] = resume_command
    results["build"] = source_build()
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{name}.json").write_text(json.dumps(results, indent=1, default=_json))
    plot(results, out / f"{name}.png")
    if gif_frames is not None:
        from diffcloth_gym.training.media import rollout_gif

        results["gif"] = str(rollout_gif(gif_engine, gif_frames, out / f"{name}.gif"))
    (out / f"{name}.md").write_text(markdown(results, name))
    return results


#: What the simulator and the harness are built from (git pathspecs from the repository's top).
CODE = (":/rust", ":/diffcloth_gym", ":/Cargo.toml", ":/Cargo.lock", ":/pyproject.toml")


def source_build() -> str:
    """The git commit of the code this runs (``-dirty`` with uncommitted changes to the simulator
    or the package; the run folders beside it always change): a run that spans sessions names
    the simulator build it was run on."""
    here = Path(__file__).resolve().parent

    def git(*args: str) -> str:
        return subprocess.run(["git", "-C", str(here), *args], capture_output=True, text=True,
                              check=True).stdout.strip()

    try:
        return git("rev-parse", "--short=12", "HEAD") + ("-dirty" if git("status", "--porcelain", "--", *CODE) else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown (not a git checkout)"


def _json(o: Any) -> Any:
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o).__name__)


def _mean(xs: Sequence[float]) -> float | None:
    return float(np.mean(xs)) if xs else None


def summarize(budget: Mapping[str, Any], budget_name: str, summaries: list[dict], seeds, methods) -> dict[str, Any]:
    apg_final = [s["final_test_loss"] for s in summaries if s["method"] == "apg" and s["final_test_loss"] is not None]
    target = 1.1 * float(np.mean(apg_final)) if apg_final else None
    for s in summaries:
        s["reach_1.1x_apg"] = steps_to_reach(s["curve"], target)
    per_method = {}
    for m in methods:
        ss = [s for s in summaries if s["method"] == m]
        reached = [s["reach_1.1x_apg"] for s in ss if s["reach_1.1x_apg"]]
        # Runs not yet evaluated (a session's deadline came before they began) count nowhere.
        done = [s for s in ss if s["final_test_loss"] is not None]
        per_method[m] = {"final_test_loss_mean": _mean([s["final_test_loss"] for s in done]),
                         "success_rate_mean": _mean([s["success_rate"] for s in done]),
                         "steps_mean": float(np.mean([s["forward"] for s in ss])),
                         "seeds_reaching": len(reached), "seeds": len(ss),
                         "eval_interval": _eval_interval(ss)}
        for key, count in (("steps_to_1.1x_apg_mean", "steps"), ("paper_steps_to_1.1x_apg_mean", "paper_steps")):
            per_method[m][key] = float(np.mean([r[count] for r in reached])) if len(reached) == len(ss) else None

    def ratio(key: str) -> float | None:
        if "apg" not in per_method or "ppo" not in per_method:
            return None
        a, p = per_method["apg"][key], per_method["ppo"][key]
        # None when a method missed the target or APG met it at step 0 (the initial policy
        # already within 1.1x: the budget is too short for the ratio to mean anything).
        return p / a if a is not None and p is not None and a > 0 else None
    return {"env_id": budget["env_id"], "budget": budget_name, "budget_config": budget,
            "test_starts": eval_starts(budget), "seeds": seeds, "methods": methods,
            "target_loss_1.1x_apg": target, "per_method": per_method,
            "ppo_over_apg_steps_to_target": ratio("steps_to_1.1x_apg_mean"),
            "ppo_over_apg_paper_steps_to_target": ratio("paper_steps_to_1.1x_apg_mean"),
            "partial": not all(s["complete"] for s in summaries), "runs": summaries,
            "machine": {"platform": platform.platform(), **threads()},
            "paper": {"apg_steps": 23_200, "ppo_steps": 1_978_000, "ratio": 85}}


def _eval_interval(summaries: Sequence[Mapping[str, Any]]) -> int | None:
    """Counted time steps between a method's regular evaluations (the resolution of its steps
    to the target): the first gap of its curves (the last one may be shorter)."""
    gaps = [s["curve"][1]["steps"] - s["curve"][0]["steps"] for s in summaries if len(s["curve"]) > 1]
    return max(gaps) if gaps else None


def plot(results: Mapping[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for s in results["runs"]:
        c = s["curve"]
        if not c:
            continue
        label = f"{s['method'].upper()} seed {s['seed']}"
        for ax, key in zip(axes, ("steps", "train_s")):
            xs = [max(p[key], 1) for p in c]
            ax.plot(xs, [p["test_loss"] for p in c], "o-", ms=3, color=COLORS.get(s["method"]), label=label,
                    alpha=0.85)
    if results.get("target_loss_1.1x_apg"):
        for ax in axes:
            ax.axhline(results["target_loss_1.1x_apg"], color="gray", ls="--", lw=1, label="1.1 x APG final")
    axes[0].set_xlabel("simulated time steps, counted (APG, SHAC: forward only; 0 drawn at 1)")
    axes[1].set_xlabel("training wall-clock seconds (0 drawn at 1)")
    for ax in axes:
        ax.set_xscale("log")
        ax.set_ylabel(f"test loss (mean over {len(results['test_starts'])} test starts)")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    tag = " (PARTIAL: budget not finished)" if results["partial"] else ""
    fig.suptitle(f"{results['env_id']}: {_title(results['methods'])}, budget '{results['budget']}'{tag}")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _title(methods: Sequence[str]) -> str:
    return " vs ".join(m.upper() for m in methods)


def _reach(reach: Mapping[str, int]) -> str:
    steps, paper = format(reach["steps"], ","), format(reach["paper_steps"], ",")
    return steps if steps == paper else f"{steps} ({paper})"


def _f(x: Any, fmt: str = "{:.4g}") -> str:
    return "-" if x is None else fmt.format(x)


def markdown(results: Mapping[str, Any], name: str) -> str:
    r = results
    lines = [f"# {r['env_id']} controller: {_title(r['methods'])} ({r['budget']} budget)", ""]
    if r["partial"]:
        lines += ["**PARTIAL RUN**: at least one run stopped before its budget (checkpointed). "
                  f"Resume with `{r.get('resume_command') or r.get('command') or 'scripts/compare_hat.py'}`.", ""]
    if r.get("command"):
        lines += [f"Command: `{r['command']}`" + (f" (code and simulator: git {r['build']})" if r.get("build") else ""), ""]
    lines += [f"Evaluated on {len(r['test_starts'])} of the env's TEST_STARTS with deterministic actions; "
              f"target loss = 1.1 x APG's final test loss = {_f(r['target_loss_1.1x_apg'])}.", "",
              "| method | seed | done | final test loss | success | time steps (counted) | paper's count | "
              "backward steps | steps to 1.1x APG (paper's count) | train s | eval s |",
              "|---|---|---|---|---|---|---|---|---|---|---|"]
    for s in r["runs"]:
        reach, started = s["reach_1.1x_apg"], bool(s["curve"])
        done = "yes" if s["complete"] else ("no" if started else "not started")
        lines.append(f"| {s['method'].upper()} | {s['seed']} | {done} | "
                     f"{_f(s['final_test_loss'])} | {_f(s['success_rate'], '{:.0%}')} | {s['forward']:,} | "
                     f"{s['paper_steps']:,} | {s['backward']:,} | "
                     f"{'-' if not started else 'not reached' if reach is None else _reach(reach)} | "
                     f"{s['train_s']:.0f} | {s['eval_s']:.0f} |")
    ratio, paper_ratio = r["ppo_over_apg_steps_to_target"], r["ppo_over_apg_paper_steps_to_target"]
    why = ("n/a (the initial policies are already within 1.1x of APG's final loss: budget too short)"
           if any(s["reach_1.1x_apg"] and s["reach_1.1x_apg"]["steps"] == 0 for s in r["runs"])
           else "n/a (a method did not reach it" + (" yet: the run is partial)" if r["partial"] else ")"))
    found = f"{ratio:.1f}x counted, {paper_ratio:.1f}x in the paper's count" if ratio and paper_ratio else why
    intervals = ", ".join(f"{m['eval_interval']:,} ({k.upper()})" for k, m in r["per_method"].items()
                          if m.get("eval_interval"))
    lines += ["", f"PPO / APG time steps to the target loss: {found} (paper: 85x, Adam 23,200 vs PPO 1,978,000, "
              "in its count).", "",
              "Steps to the target are those of the first evaluation at or below it"
              + (f"; evaluations every {intervals} counted steps bound their resolution." if intervals else "."), "",
              "Counting: time steps are every step the simulator completed in training, read from the "
              "engine's per-member step counters (evaluation apart). APG's and SHAC's backward passes are "
              "one-step adjoints per recorded step, listed as 'backward steps' and not added. The paper "
              "counts one rollout per APG epoch (epochs x horizon, 'paper's count') although its code rolls "
              "out 20.", "",
              f"Threads: simulator {r['machine']['simulator_threads']}, torch {r['machine']['torch_threads']}, "
              f"cores {r['machine']['cpu_count']}. Wall clock of this invocation: {r['wall_s']:.0f} s.", "",
              f"![test loss vs time steps]({name}.png)", ""]
    if r.get("gif"):
        lines += [f"![APG policy from test starts]({name}.gif)", ""]
    return "\n".join(lines)
