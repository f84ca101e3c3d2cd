"""PPO (stable-baselines3) on the batched ``ClothSB3VecEnv``: the same observation as APG, the
same policy size (MLP 64-64 tanh, for the Gaussian's mean and, separately, the value), reward
= minus the step's loss (the env's own reward: the paper's fairness rule).

Training runs one rollout at a time; every ``eval_every`` time steps (rounded up to whole
rollouts) the policy's mean action is evaluated on ``TEST_STARTS`` (the curve), and after every
rollout a checkpoint is written (a session that stops loses at most one rollout): the SB3
model (policy, Adam, ``num_timesteps``, last observation), the
RNG states (torch samples the actions, numpy shuffles the minibatches), the adapter's start
generators and the members' states, the step counts and the clock. With ``n_steps`` a
multiple of the horizon every checkpoint falls on an episode boundary (all members just
reset), so a resumed run continues bitwise as the uninterrupted one; otherwise the members'
episodes restart from their saved positions and velocities only and the resumed run may
differ (the trainer warns).

Logs: SB3's own (``sb3/progress.csv``; TensorBoard too when ``tensorboard`` is installed) and
``eval.csv`` (the curve).
"""

from __future__ import annotations

import csv
import io
import time
import warnings
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import torch
from tqdm.auto import tqdm

from diffcloth_gym.training.accounting import Clock, count_steps, paper_count, threads
from diffcloth_gym.training.config import load, merged
from diffcloth_gym.training.evaluate import Evaluator, test_starts
from diffcloth_gym.training.runlog import (CsvLog, check_physics, load_checkpoint, physics_fingerprint, rng_states,
                                          save_atomic, set_rng_states)


def _callback(bar):
    from stable_baselines3.common.callbacks import BaseCallback

    class _Progress(BaseCallback):
        def _on_step(self) -> bool:
            bar.update(self.training_env.num_envs)
            return True

    return _Progress()


def _fixed(cfg: Mapping[str, Any]) -> dict:
    """The settings a run cannot change when resumed (its length may grow)."""
    return {k: v for k, v in cfg.items() if k != "timesteps"}


class PPOTrainer:
    """One PPO run in ``run_dir`` (resumed from its checkpoint when there is one)."""

    def __init__(self, cfg: Mapping[str, Any] | None = None, run_dir: str | Path | None = None, seed: int = 0,
                 resume: bool = True, progress: bool = True, eval_starts: list | None = None):
        from stable_baselines3 import PPO
        from stable_baselines3.common.vec_env import VecMonitor

        from diffcloth_gym.envs.sb3 import ClothSB3VecEnv

        self.cfg = merged(load("hat_ppo"), cfg or {})
        c = self.cfg
        torch.set_num_threads(int(c["torch_threads"]))
        self.seed, self.progress = seed, progress
        self.run_dir = Path(run_dir) if run_dir is not None else None
        self.adapter = ClothSB3VecEnv(c["env_id"], num_envs=int(c["num_envs"]), **c["env"])
        self.engine, self.task = self.adapter.engine, self.adapter.task
        self.counter = count_steps(self.engine)
        self.venv = VecMonitor(self.adapter)
        self.rollout = int(c["num_envs"]) * int(c["n_steps"])
        if int(c["n_steps"]) % self.task.horizon:
            warnings.warn(f"ppo: n_steps {c['n_steps']} is not a multiple of the horizon {self.task.horizon}: "
                          "checkpoints fall inside episodes and a resumed run is not bitwise the "
                          "uninterrupted one", stacklevel=2)
        kwargs = dict(learning_rate=float(c["lr"]), n_steps=int(c["n_steps"]), batch_size=int(c["batch_size"]),
                      n_epochs=int(c["n_epochs"]), gamma=float(c["gamma"]), gae_lambda=float(c["gae_lambda"]),
                      clip_range=float(c["clip_range"]), ent_coef=float(c["ent_coef"]),
                      max_grad_norm=float(c["max_grad_norm"]),
                      policy_kwargs=dict(net_arch=list(c["hidden"]), activation_fn=torch.nn.Tanh,
                                         log_std_init=float(c["log_std_init"])),
                      seed=seed, device="cpu", verbose=0)
        self.clock = Clock()
        self.curve: list[dict] = []
        self.eval_steps = 0
        self.eval_starts = list(test_starts(c["env_id"]) if eval_starts is None else eval_starts)
        self._evaluator = Evaluator(c["env_id"], self.eval_starts, c["env"])
        self.last_eval: list[dict] = []
        ck = load_checkpoint(self.run_dir / "checkpoint.pt") if (self.run_dir and resume) else None
        if ck is None:
            self.adapter.seed(seed)
            self.model = PPO("MlpPolicy", self.venv, **kwargs)
        else:
            if _fixed(ck["cfg"]) != _fixed(self.cfg) or ck["seed"] != seed:
                raise ValueError(f"{self.run_dir}: its checkpoint was made with another config or seed; "
                                 "use another run folder or resume=False")
            check_physics(ck, self.engine, self.run_dir)
            self.model = PPO.load(io.BytesIO(ck["model"]), env=self.venv, device="cpu")
            self._restore(ck)
        self.eval_log = None
        self._logger_set = False
        if self.run_dir is not None:
            self.run_dir.mkdir(parents=True, exist_ok=True)
            self.eval_log = CsvLog(self.run_dir / "eval.csv")
            if ck is not None:
                self.eval_log.truncate("steps", self.model.num_timesteps)

    # -- checkpoints -----------------------------------------------------------------------------
    def state(self) -> dict[str, Any]:
        buf = io.BytesIO()
        self.model.save(buf)
        e = self.engine
        members = e.snapshot()
        return {"method": "ppo", "cfg": self.cfg, "seed": self.seed, "model": buf.getvalue(),
                "num_timesteps": self.model.num_timesteps, "members": members,
                "adapter_rngs": self.adapter._rngs, "counts": self.counter.snapshot(),
                "eval_steps": self.eval_steps, "clock": self.clock.state(), "curve": self.curve,
                "last_eval": self.last_eval, "rng": rng_states(), "physics": physics_fingerprint(self.engine)}

    def _restore(self, ck: dict) -> None:
        obs = self.engine.restore(ck["members"])
        self.adapter._rngs = ck["adapter_rngs"]
        self.model._last_obs = obs.astype(np.float64)
        self.counter.restore(ck["counts"])
        self.eval_steps, self.curve, self.last_eval = ck["eval_steps"], ck["curve"], ck["last_eval"]
        self.clock.train_s, self.clock.eval_s = ck["clock"]["train_s"], ck["clock"]["eval_s"]
        set_rng_states(ck["rng"])

    def save(self) -> None:
        if self.run_dir is not None:
            save_atomic(self.state(), self.run_dir / "checkpoint.pt")

    # -- evaluation and the loop -------------------------------------------------------------------
    def evaluate(self, frames_every: int | None = None):
        return self._evaluator(self.model, frames_every)

    def _eval_point(self) -> None:
        self.clock.start()
        ev = self.evaluate()
        self.clock.stop("eval")
        self.eval_steps += ev.steps
        steps = self.counter.forward
        point = {"steps": steps, "paper_steps": paper_count("ppo", None, self.task.horizon, steps),
                 "backward_steps": 0, "train_s": self.clock.train_s, "test_loss": ev.mean_loss,
                 "success_rate": ev.success_rate}
        self.curve.append(point)
        self.last_eval = ev.per_start()
        if self.eval_log is not None:
            self.eval_log.write(point)

    def train(self, timesteps: int | None = None, deadline: float | None = None,
              max_rollouts: int | None = None) -> dict[str, Any]:
        """Trains up to ``timesteps`` in total (default the config's), whole rollouts,
        evaluating every ``eval_every`` time steps (rounded up to whole rollouts) and at the end.
        A checkpoint follows every rollout, so a killed run loses at most one. Stops early
        (after a checkpoint, resumable, without an extra evaluation) once ``time.time()`` passes
        ``deadline`` or after ``max_rollouts`` rollouts of this call; a run not yet begun does not
        start after its deadline."""
        total = int(self.cfg["timesteps"] if timesteps is None else timesteps)
        self.target_timesteps = total
        chunk = max(1, -(-int(self.cfg["eval_every"]) // self.rollout)) * self.rollout
        if not self.curve and deadline is not None and time.time() >= deadline:
            return self.summary()
        self._set_logger()
        if not self.curve:
            self._eval_point()
            self.save()
        bar = tqdm(total=total, initial=self.model.num_timesteps, desc=f"ppo seed {self.seed}",
                   disable=not self.progress, unit="step")
        done = 0
        while (self.model.num_timesteps < total and (deadline is None or time.time() < deadline)
               and (max_rollouts is None or done < max_rollouts)):
            self.clock.start()
            self.model.learn(self.rollout, reset_num_timesteps=False, callback=_callback(bar))
            self.clock.stop("train")
            done += 1
            if self.model.num_timesteps % chunk == 0 or self.model.num_timesteps >= total:
                self._eval_point()
                bar.set_postfix(test=f"{self.curve[-1]['test_loss']:.4g}")
            self.save()
        bar.close()
        return self.summary()

    def _set_logger(self) -> None:
        """SB3's CSV (and TensorBoard) logs in the run folder, made when training starts: a run
        whose turn never comes this session leaves no empty event file."""
        from stable_baselines3.common.logger import configure

        if self.run_dir is None or self._logger_set:
            return
        formats = ["csv"]
        try:
            import tensorboard  # noqa: F401

            formats.append("tensorboard")
        except ImportError:
            pass
        csv_path = self.run_dir / "sb3" / "progress.csv"
        previous = _csv_rows_up_to(csv_path, self.model.num_timesteps) if csv_path.exists() else None
        logger = configure(str(self.run_dir / "sb3"), formats)
        if previous is not None:
            _continue_csv(logger, *previous)
        self.model.set_logger(logger)
        self._logger_set = True

    def summary(self) -> dict[str, Any]:
        last = self.curve[-1] if self.curve else {}
        target = getattr(self, "target_timesteps", int(self.cfg["timesteps"]))
        return {"method": "ppo", "seed": self.seed, "budget_timesteps": target,
                "complete": self.model.num_timesteps >= target, "final_test_loss": last.get("test_loss"),
                "per_start": self.last_eval,
                "success_rate": last.get("success_rate"), "curve": self.curve, **self.counter.snapshot(),
                "num_timesteps": self.model.num_timesteps,
                "paper_steps": paper_count("ppo", None, self.task.horizon, self.counter.forward),
                "eval_steps": self.eval_steps, **self.clock.state(), **threads()}


def _csv_rows_up_to(path: Path, timesteps: int) -> tuple[list[str], list[list[str]]] | None:
    """A run's earlier SB3 log: header and the rows up to the checkpoint's time steps (a run
    killed between a rollout's log and its checkpoint logged a rollout it will redo)."""
    with path.open(newline="") as f:
        rows = list(csv.reader(f))
    if not rows:
        return None
    header, body = rows[0], rows[1:]
    col = header.index("time/total_timesteps") if "time/total_timesteps" in header else None
    keep = [r for r in body if col is None or (r[col] != "" and float(r[col]) <= timesteps)]
    return header, keep


def _continue_csv(logger: Any, header: list[str], rows: list[list[str]]) -> None:
    """SB3's CSV writer opens progress.csv with "w+" (a resumed run would erase its history):
    write the earlier rows back and give the writer their columns, so its later rows line up
    (it rewrites the file itself when a row brings new columns)."""
    from stable_baselines3.common.logger import CSVOutputFormat

    for fmt in logger.output_formats:
        if isinstance(fmt, CSVOutputFormat):
            csv.writer(fmt.file, lineterminator="\n").writerows([header, *rows])
            fmt.file.flush()
            fmt.keys = list(header)


def train_ppo(cfg: Mapping[str, Any] | None = None, run_dir: str | Path | None = None, seed: int = 0,
              **kwargs: Any) -> PPOTrainer:
    """Trains (or resumes) a PPO run; returns the trainer (its ``model`` and ``summary()``)."""
    trainer = PPOTrainer(cfg, run_dir, seed, **kwargs)
    trainer.train()
    return trainer
