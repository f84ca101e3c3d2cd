"""Every simulated time step counted, from the engine's own counters (not estimated from
epochs x batch x horizon), plus wall clock and threads.

How: ``count_steps(engine, counter)`` puts a thin proxy in front of the engine's Rust batch.
The batch counts each member's steps since its last reset (``step_counts()``); the proxy
collects a member's count just before that member is reset, so

    forward = sum of collected counts + the members' current counts

is every step the simulator completed, whoever called it (a training rollout, the vector
env's NEXT_STEP autoreset that steps a member from its new start and throws the step away,
an SB3 same-step reset). ``attempted`` counts member-steps handed to the batch (``step`` calls
x members), which also includes steps the solver refused; the two agree unless a step failed.

Backward steps: one ``backward_step`` call is the one-step adjoint of one recorded step on
every member, so it counts ``members`` backward steps. A backward step is not a simulated
time step (it re-simulates nothing, see ``envs/engine.py``); it is reported on its own
(about as costly as a forward step for the Hat).

The paper's counting (Sec. 6.5, Fig. 12: Adam 23,200 = 58 epochs x 400 steps) counts one
rollout per epoch although the reference code rolls out 20: ``paper_count`` gives
``epochs x horizon`` for APG beside our count; for PPO the two agree (env steps).
"""

from __future__ import annotations

import os
import time
from dataclasses import asdict, dataclass, field
from typing import Any


@dataclass
class StepCounter:
    """Counts of one engine (or several: a counter may be shared)."""

    collected: int = 0        # steps of members already reset
    attempted: int = 0        # member-steps handed to the batch
    backward: int = 0         # one-step adjoints (member-steps)
    engines: list = field(default_factory=list, repr=False)

    @property
    def forward(self) -> int:
        """Simulated time steps so far (collected + the members' current episodes)."""
        return self.collected + sum(sum(e.batch.inner.step_counts()) for e in self.engines)

    def snapshot(self) -> dict[str, int]:
        return {"forward": self.forward, "attempted": self.attempted, "backward": self.backward}

    def restore(self, counts: dict[str, int]) -> None:
        """Continues a resumed run's counts (the engines' current episodes start at 0)."""
        self.collected = int(counts["forward"]) - sum(sum(e.batch.inner.step_counts()) for e in self.engines)
        self.attempted = int(counts["attempted"])
        self.backward = int(counts["backward"])


class _CountingBatch:
    """Forwards every call to the Rust batch; counts steps, resets and one-step adjoints."""

    def __init__(self, inner: Any, counter: StepCounter):
        self.inner, self.counter = inner, counter

    def step(self, *args, **kwargs):
        self.counter.attempted += len(self.inner)
        return self.inner.step(*args, **kwargs)

    def reset(self, index, *args, **kwargs):
        self.counter.collected += self.inner.step_counts()[index]
        return self.inner.reset(index, *args, **kwargs)

    def backward_step(self, *args, **kwargs):
        self.counter.backward += len(self.inner)
        return self.inner.backward_step(*args, **kwargs)

    def __len__(self):
        return len(self.inner)

    def __getattr__(self, name):
        return getattr(self.inner, name)


def count_steps(engine: Any, counter: StepCounter | None = None) -> StepCounter:
    """Counts ``engine``'s steps in ``counter`` (a new one by default) from now on."""
    counter = counter or StepCounter()
    if not isinstance(engine.batch, _CountingBatch):
        engine.batch = _CountingBatch(engine.batch, counter)
    else:
        engine.batch.counter = counter
    counter.engines.append(engine)
    return counter


def engine_of(env: Any) -> Any:
    """The ``ClothEngine`` under a Gymnasium env, vector env or SB3 adapter (or wrapper)."""
    for obj in (env, getattr(env, "unwrapped", None), getattr(env, "venv", None)):
        if obj is not None and hasattr(obj, "engine"):
            return obj.engine
    raise TypeError(f"{type(env).__name__} has no cloth engine")


def threads() -> dict[str, Any]:
    """CPU threads in use: the simulator's (rayon, ``RAYON_NUM_THREADS``, else every core) and
    torch's intra-op threads."""
    import torch

    rayon = os.environ.get("RAYON_NUM_THREADS")
    return {"simulator_threads": int(rayon) if rayon else os.cpu_count(), "torch_threads": torch.get_num_threads(),
            "cpu_count": os.cpu_count()}


@dataclass
class Clock:
    """Wall-clock seconds of training (evaluation timed apart), resumable."""

    train_s: float = 0.0
    eval_s: float = 0.0
    _t0: float | None = field(default=None, repr=False)

    def start(self) -> None:
        self._t0 = time.perf_counter()

    def stop(self, kind: str = "train") -> float:
        dt = time.perf_counter() - (self._t0 or time.perf_counter())
        setattr(self, f"{kind}_s", getattr(self, f"{kind}_s") + dt)
        self._t0 = None
        return dt

    def state(self) -> dict[str, float]:
        d = asdict(self)
        d.pop("_t0")
        return d


def paper_count(method: str, epochs: int | None, horizon: int, forward: int) -> int:
    """The paper's way of counting training time steps: one rollout per APG epoch (``epochs x
    horizon``); env steps for PPO (same as ours)."""
    return epochs * horizon if method == "apg" and epochs is not None else forward
