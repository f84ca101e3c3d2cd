"""What one optimization run leaves behind (:class:`Run`), its CSV log and JSON results, the
shared initial guesses (same seed, same start for every method) and the progress bar."""

from __future__ import annotations

import csv
import json
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from diffcloth_gym.optim.parameterization import Parameterization


def initial_guess(p: Parameterization, seed: int, spread: float = 1.0) -> np.ndarray:
    """A seeded random start in the unit box: ``0.5 + spread * U(-0.5, 0.5)`` per entry (the
    same for every method given the same seed)."""
    rng = np.random.default_rng(seed)
    return 0.5 + spread * rng.uniform(-0.5, 0.5, p.size)


@dataclass
class Run:
    """One optimizer run: its per-evaluation history (steps used so far, loss, best so far)
    and its outcome. ``theta`` values are in the parameterization's units."""

    method: str
    seed: int
    budget: int | None
    initial_loss: float
    best_loss: float
    best_theta: list
    steps_used: int
    evaluations: int
    stop: str
    seconds: float
    unconverged_steps: int
    gradient_warnings: list
    history: list = field(default_factory=list)

    def to_dict(self) -> dict:
        return asdict(self)

    def steps_to(self, level: float) -> int | None:
        """Steps used when the best loss first reached ``level`` (None: never)."""
        return next((h["steps"] for h in self.history if h["best"] <= level), None)


def finish(objective, method: str, seed: int, stop: str) -> Run:
    h = objective.history
    return Run(method=method, seed=seed, budget=objective.budget, initial_loss=h[0]["loss"] if h else float("nan"),
               best_loss=float(objective.best_loss),
               best_theta=[] if objective.best_theta is None else objective.best_theta.tolist(),
               steps_used=objective.steps_used, evaluations=len(h), stop=stop,
               seconds=h[-1]["seconds"] if h else 0.0, unconverged_steps=objective.unconverged_steps,
               gradient_warnings=list(objective.gradient_warnings), history=list(h))


def write_csv(runs: list[Run], path: str | Path) -> None:
    """One row per evaluation: method, seed, evaluation, steps, loss, best, gradient, seconds."""
    cols = ["method", "seed", "evaluation", "steps", "loss", "best", "gradient", "grad_norm", "seconds"]
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=cols)
        w.writeheader()
        for r in runs:
            for h in r.history:
                w.writerow({"method": r.method, "seed": r.seed, **{k: h[k] for k in cols[2:]}})


def write_json(runs: list[Run], path: str | Path, meta: dict | None = None) -> None:
    Path(path).write_text(json.dumps({"meta": meta or {}, "runs": [r.to_dict() for r in runs]}, indent=1))


@contextmanager
def progress(objective, desc: str, enabled: bool = True):
    """A tqdm bar over the step budget, advanced by every evaluation (shows the best loss)."""
    if not enabled:
        yield
        return
    from tqdm.auto import tqdm

    bar = tqdm(total=objective.budget, desc=desc, unit="step", leave=False, dynamic_ncols=True)
    last = [0]

    def update(entry):
        bar.update(entry["steps"] - last[0])
        last[0] = entry["steps"]
        bar.set_postfix(best=f"{entry['best']:.3g}")

    objective.callbacks.append(update)
    try:
        yield
    finally:
        objective.callbacks.remove(update)
        bar.close()
