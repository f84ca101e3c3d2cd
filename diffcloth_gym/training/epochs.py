"""What every epoch-based trainer through the simulator shares (APG and SHAC): the vector env
and its step counter, the policy and its Adam optimizer, evaluation on the test starts every
``eval_every`` epochs, checkpoints every epoch (resumed bitwise), the clipped-and-logged
optimizer step, the training loop with a deadline, and the run's summary.

A subclass names its ``method`` and default config, builds what else it needs in ``build()``
(SHAC's critic), adds it to checkpoints in ``extra_state`` / ``load_extra_state``, and runs one
epoch in ``run_epoch``.

Starts: epoch ``e`` of run seed ``s`` resets member ``i`` with seed ``1_000_003 s + e batch + i``,
so every epoch's starts are fixed by the run seed and a resumed run draws the same ones.
"""

from __future__ import annotations

import math
import time
import warnings
from pathlib import Path
from typing import Any, Mapping

import gymnasium as gym
import torch
from tqdm.auto import tqdm

from diffcloth_gym.training.accounting import Clock, count_steps, engine_of, paper_count, threads
from diffcloth_gym.training.config import load, merged
from diffcloth_gym.training.evaluate import Evaluator, test_starts
from diffcloth_gym.training.policy import MLPPolicy
from diffcloth_gym.training.runlog import (CsvLog, check_physics, load_checkpoint, physics_fingerprint, rng_states,
                                          save_atomic, set_rng_states)


def epoch_seed(run_seed: int, epoch: int, batch: int) -> int:
    return 1_000_003 * run_seed + epoch * batch


def _fixed(cfg: Mapping[str, Any]) -> dict:
    """The settings a run cannot change when resumed (its length may grow)."""
    return {k: v for k, v in cfg.items() if k != "epochs"}


def _tensorboard_writer(folder: Path, purge_step: int):
    """A TensorBoard writer when ``tensorboard`` is installed (else None: the CSV logs stay).
    ``purge_step`` drops events a killed run wrote after its last checkpoint."""
    try:
        from torch.utils.tensorboard import SummaryWriter
    except ImportError:
        return None
    return SummaryWriter(str(folder), purge_step=purge_step)


def _scalars(writer, group: str, row: Mapping[str, Any], step: int) -> None:
    """The row's numbers as scalars ``group/key`` at ``step`` (simulated time steps)."""
    if writer is None:
        return
    for key, value in row.items():
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            writer.add_scalar(f"{group}/{key}", value, step)
    writer.flush()


class AdjointWarnings:
    """Collects the simulator's gradient warnings (``"diffcloth gradient ..."``) raised inside
    the block, passes every other warning on, and says once per block how many there were."""

    def __init__(self, where: str):
        self.where, self.messages = where, []

    def __enter__(self) -> "AdjointWarnings":
        self._catcher = warnings.catch_warnings(record=True)
        self._caught = self._catcher.__enter__()
        warnings.simplefilter("always")
        return self

    def __exit__(self, *exc) -> None:
        self._catcher.__exit__(*exc)
        for w in self._caught:
            if "diffcloth gradient" in str(w.message):
                self.messages.append(str(w.message))
            else:
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        if self.messages:
            tqdm.write(f"{self.where}: {len(self.messages)} adjoint warning(s), first: {self.messages[0]}")


class EpochTrainer:
    """One run in ``run_dir`` (resumed from its checkpoint when there is one)."""

    method = "?"
    default_config = "?"

    def __init__(self, cfg: Mapping[str, Any] | None = None, run_dir: str | Path | None = None, seed: int = 0,
                 resume: bool = True, progress: bool = True, eval_starts: list | None = None):
        self.cfg = merged(load(self.default_config), cfg or {})
        c = self.cfg
        torch.set_num_threads(int(c["torch_threads"]))
        self.seed, self.progress = seed, progress
        self.run_dir = Path(run_dir) if run_dir is not None else None
        self.env = gym.make_vec(c["env_id"], num_envs=int(c["batch"]), **c["env"])
        self.engine = engine_of(self.env)
        self.task = self.engine.task
        self.counter = count_steps(self.engine)
        self.policy = MLPPolicy(self.task.obs_dim, self.task.action_dim, c["hidden"], self.task.action_bound,
                                seed=seed, last_layer_scale=c["last_layer_scale"])
        self.optimizer = torch.optim.Adam(self.policy.parameters(), lr=float(c["lr"]))
        self.epoch = 0
        self.clock = Clock()
        self.curve: list[dict] = []
        self.clip_count = 0
        self.eval_starts = list(test_starts(c["env_id"]) if eval_starts is None else eval_starts)
        self._evaluator = Evaluator(c["env_id"], self.eval_starts, c["env"])
        self.last_eval: list[dict] = []
        self.eval_steps = 0
        self.train_log = self.eval_log = None
        self._tensorboard, self._tensorboard_purge = None, None
        self.build()
        if self.run_dir is not None:
            self.run_dir.mkdir(parents=True, exist_ok=True)
            self.train_log = CsvLog(self.run_dir / "train.csv")
            self.eval_log = CsvLog(self.run_dir / "eval.csv")
            if resume:
                self._resume()
            # Opened on first write: a run whose turn never comes this session leaves no file.
            self._tensorboard_purge = self.counter.forward

    @property
    def tensorboard(self):
        """The run's TensorBoard writer (None without a run folder or ``tensorboard``)."""
        if self._tensorboard is None and self._tensorboard_purge is not None:
            self._tensorboard = _tensorboard_writer(self.run_dir / "tb", purge_step=self._tensorboard_purge)
            self._tensorboard_purge = None
        return self._tensorboard

    # -- hooks -----------------------------------------------------------------------------------
    def build(self) -> None:
        """Builds the method's own parts (after the policy, before a resume)."""

    def extra_state(self) -> dict[str, Any]:
        return {}

    def load_extra_state(self, ck: Mapping[str, Any]) -> None:
        pass

    def run_epoch(self) -> dict[str, Any]:
        raise NotImplementedError

    # -- checkpoints -----------------------------------------------------------------------------
    def state(self) -> dict[str, Any]:
        return {"method": self.method, "cfg": self.cfg, "seed": self.seed, "epoch": self.epoch,
                "policy": self.policy.state_dict(), "policy_config": self.policy.config(),
                "optimizer": self.optimizer.state_dict(), "counts": self.counter.snapshot(),
                "eval_steps": self.eval_steps, "clock": self.clock.state(), "curve": self.curve,
                "last_eval": self.last_eval, "clip_count": self.clip_count, "rng": rng_states(),
                "physics": physics_fingerprint(self.engine), **self.extra_state()}

    def _resume(self) -> None:
        ck = load_checkpoint(self.run_dir / "checkpoint.pt")
        if ck is None:
            return
        if _fixed(ck["cfg"]) != _fixed(self.cfg) or ck["seed"] != self.seed:
            raise ValueError(f"{self.run_dir}: its checkpoint was made with another config or seed; "
                             "use another run folder or resume=False")
        check_physics(ck, self.engine, self.run_dir)
        self.policy.load_state_dict(ck["policy"])
        self.optimizer.load_state_dict(ck["optimizer"])
        self.epoch, self.curve, self.clip_count = ck["epoch"], ck["curve"], ck["clip_count"]
        self.last_eval = ck["last_eval"]
        self.counter.restore(ck["counts"])
        self.eval_steps = ck["eval_steps"]
        self.clock.train_s, self.clock.eval_s = ck["clock"]["train_s"], ck["clock"]["eval_s"]
        self.load_extra_state(ck)
        set_rng_states(ck["rng"])
        self.train_log.truncate("epoch", self.epoch)
        self.eval_log.truncate("epoch", self.epoch)

    def save(self) -> None:
        if self.run_dir is not None:
            save_atomic(self.state(), self.run_dir / "checkpoint.pt")

    # -- the optimizer step ----------------------------------------------------------------------
    def clipped_step(self, optimizer: torch.optim.Optimizer, parameters, grad_norm: float,
                     clip: float, what: str) -> tuple[bool, bool]:
        """One optimizer step on gradients of norm ``grad_norm``: skipped (and said) when the
        norm is not finite, clipped to ``clip`` when above it (0: never; said the first time,
        logged every time by the caller). Returns (clipped, skipped)."""
        parameters = list(parameters)
        if not math.isfinite(grad_norm):
            tqdm.write(f"{self.method} epoch {self.epoch + 1}: non-finite {what} gradient norm {grad_norm}: "
                       "step skipped")
            return False, True
        clipped = clip > 0 and grad_norm > clip
        if clipped:
            torch.nn.utils.clip_grad_norm_(parameters, clip)
            if self.clip_count == 0:
                tqdm.write(f"{self.method}: {what} gradient norm {grad_norm:.3g} clipped to {clip} (logged in "
                           "train.csv, column 'clipped')")
            self.clip_count += 1
        optimizer.step()
        return clipped, False

    def cut_graph(self, obs: torch.Tensor) -> torch.Tensor:
        """Detaches the rollout's state (the engine's graph and the observation); the next
        step's record starts from the same values without history."""
        self.engine.detach_graph()
        return obs.detach()

    # -- evaluation and the loop -------------------------------------------------------------------
    def evaluate(self, frames_every: int | None = None):
        return self._evaluator(self.policy, frames_every)

    def _eval_point(self) -> None:
        self.clock.start()
        ev = self.evaluate()
        self.clock.stop("eval")
        self.eval_steps += ev.steps
        point = {"epoch": self.epoch, "steps": self.counter.forward,
                 "paper_steps": paper_count(self.method, self.epoch, self.task.horizon, self.counter.forward),
                 "backward_steps": self.counter.backward, "train_s": self.clock.train_s,
                 "test_loss": ev.mean_loss, "success_rate": ev.success_rate}
        self.curve.append(point)
        self.last_eval = ev.per_start()
        if self.eval_log is not None:
            self.eval_log.write(point)
            _scalars(self.tensorboard, "eval", point, point["steps"])

    def train(self, epochs: int | None = None, deadline: float | None = None) -> dict[str, Any]:
        """Trains up to ``epochs`` in total (default the config's), evaluating every
        ``eval_every`` epochs and at the end; stops early (after a checkpoint, resumable) once
        ``time.time()`` passes ``deadline`` (a run not yet begun does not start). Returns the
        run's summary."""
        epochs = int(self.cfg["epochs"] if epochs is None else epochs)
        self.target_epochs = epochs
        every = int(self.cfg["eval_every"])
        if not self.curve:
            if deadline is not None and time.time() >= deadline:
                return self.summary()  # out of time before it began: not even its first evaluation
            self._eval_point()
            self.save()
        bar = tqdm(total=epochs, initial=self.epoch, desc=f"{self.method} seed {self.seed}",
                   disable=not self.progress, unit="epoch")
        while self.epoch < epochs and (deadline is None or time.time() < deadline):
            self.clock.start()
            row = self.run_epoch()
            row["epoch_s"] = self.clock.stop("train")
            if self.train_log is not None:
                self.train_log.write(row)
                _scalars(self.tensorboard, "train", row, self.counter.forward)
            # A deadline stops after the checkpoint without an extra evaluation: the curve of a
            # run done in parts is the uninterrupted run's, and no session pays for an off-grid one.
            if (every and self.epoch % every == 0) or self.epoch == epochs:
                self._eval_point()
            self.save()
            bar.update(1)
            bar.set_postfix(loss=f"{row['train_loss']:.4g}", grad=f"{row['grad_norm']:.3g}",
                            test=f"{self.curve[-1]['test_loss']:.4g}")
        bar.close()
        return self.summary()

    def summary(self) -> dict[str, Any]:
        last = self.curve[-1] if self.curve else {}
        target = getattr(self, "target_epochs", int(self.cfg["epochs"]))
        return {"method": self.method, "seed": self.seed, "epochs": self.epoch, "budget_epochs": target,
                "complete": self.epoch >= target, "final_test_loss": last.get("test_loss"),
                "final_eval_epoch": last.get("epoch"), "per_start": self.last_eval,
                "success_rate": last.get("success_rate"), "curve": self.curve, **self.counter.snapshot(),
                "paper_steps": paper_count(self.method, self.epoch, self.task.horizon, self.counter.forward),
                "eval_steps": self.eval_steps, "clipped_epochs": self.clip_count, **self.clock.state(),
                **threads()}
