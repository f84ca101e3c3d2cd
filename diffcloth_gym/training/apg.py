"""Analytic policy gradients: the paper's hat controller (Sec. 6.5; the reference
``hatController.py``) trained through the simulator's adjoint.

Each epoch rolls out ``batch`` random starts (default 20, the reference's) in parallel on the
vector env's batched ``step_grad``, averages the episode loss ``L_i = -sum_t r_t`` over the
members, backpropagates through the whole closed loop (policy -> effectors -> cloth ->
observation -> policy ...) and takes one Adam step.

Options (``configs/hat_apg.toml``):

- ``clip_grad_norm``: clip the batch gradient's norm (the reference clips at 1.0). Every epoch
  logs the norm before clipping and whether the clip acted (``clipped``); the first time it
  acts it also says so on the console. 0 turns it off.
- ``window``: truncated backpropagation (SHAC-style, Xu et al. 2022): the episode is cut into
  windows of ``window`` steps; each window's loss is backpropagated on its own and the state
  (cloth, effectors, observation) is detached between windows, so no gradient crosses a window
  boundary. 0 = the whole horizon (the paper's).
- ``member_grad_stats``: per-member gradients ``dL_i/dtheta`` (from zero weight perturbations,
  see ``policy.py``), logged as their mean norm and the batch's variance ``mean_i |g_i - g|^2``.

Starts: epoch ``e`` of run seed ``s`` resets member ``i`` with seed ``1_000_003 s + e batch + i``,
so every epoch's starts are fixed by the run seed and a resumed run draws the same ones.
Checkpoints (policy, Adam, epoch, counts, clock, RNG states, curve) are written every epoch.
"""

from __future__ import annotations

import math
import time
import warnings
from pathlib import Path
from typing import Any, Mapping

import gymnasium as gym
import numpy as np
import torch
from tqdm.auto import tqdm

from diffcloth_gym.training.accounting import Clock, count_steps, engine_of, paper_count, threads
from diffcloth_gym.training.config import load, merged
from diffcloth_gym.training.evaluate import evaluate, make_eval_env, test_starts
from diffcloth_gym.training.policy import MLPPolicy
from diffcloth_gym.training.runlog import CsvLog, load_checkpoint, rng_states, save_atomic, set_rng_states


def epoch_seed(run_seed: int, epoch: int, batch: int) -> int:
    return 1_000_003 * run_seed + epoch * batch


def _fixed(cfg: Mapping[str, Any]) -> dict:
    """The settings a run cannot change when resumed (its length may grow)."""
    return {k: v for k, v in cfg.items() if k != "epochs"}


class APGTrainer:
    """One APG run in ``run_dir`` (resumed from its checkpoint when there is one)."""

    def __init__(self, cfg: Mapping[str, Any] | None = None, run_dir: str | Path | None = None, seed: int = 0,
                 resume: bool = True, progress: bool = True, eval_starts: list | None = None):
        self.cfg = merged(load("hat_apg"), cfg or {})
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
        self._eval_env = None
        self.last_eval: list[dict] = []
        self.eval_steps = 0
        self.train_log = self.eval_log = None
        if self.run_dir is not None:
            self.run_dir.mkdir(parents=True, exist_ok=True)
            self.train_log = CsvLog(self.run_dir / "train.csv")
            self.eval_log = CsvLog(self.run_dir / "eval.csv")
            if resume:
                self._resume()

    # -- checkpoints -----------------------------------------------------------------------------
    def state(self) -> dict[str, Any]:
        return {"method": "apg", "cfg": self.cfg, "seed": self.seed, "epoch": self.epoch,
                "policy": self.policy.state_dict(), "policy_config": self.policy.config(),
                "optimizer": self.optimizer.state_dict(), "counts": self.counter.snapshot(),
                "eval_steps": self.eval_steps, "clock": self.clock.state(), "curve": self.curve,
                "last_eval": self.last_eval, "clip_count": self.clip_count, "rng": rng_states()}

    def _resume(self) -> None:
        ck = load_checkpoint(self.run_dir / "checkpoint.pt")
        if ck is None:
            return
        if _fixed(ck["cfg"]) != _fixed(self.cfg) or ck["seed"] != self.seed:
            raise ValueError(f"{self.run_dir}: its checkpoint was made with another config or seed; "
                             "use another run folder or resume=False")
        self.policy.load_state_dict(ck["policy"])
        self.optimizer.load_state_dict(ck["optimizer"])
        self.epoch, self.curve, self.clip_count = ck["epoch"], ck["curve"], ck["clip_count"]
        self.last_eval = ck["last_eval"]
        self.counter.restore(ck["counts"])
        self.eval_steps = ck["eval_steps"]
        self.clock.train_s, self.clock.eval_s = ck["clock"]["train_s"], ck["clock"]["eval_s"]
        set_rng_states(ck["rng"])
        self.train_log.truncate("epoch", self.epoch)
        self.eval_log.truncate("epoch", self.epoch)

    def save(self) -> None:
        if self.run_dir is not None:
            save_atomic(self.state(), self.run_dir / "checkpoint.pt")

    # -- one epoch -------------------------------------------------------------------------------
    def run_epoch(self) -> dict[str, Any]:
        """Rolls out the batch from this epoch's starts, backpropagates, takes one Adam step."""
        c, env, policy = self.cfg, self.env, self.policy
        n, horizon = int(c["batch"]), self.task.horizon
        window = int(c["window"]) or horizon
        obs, _ = env.reset(seed=epoch_seed(self.seed, self.epoch, n))
        obs = torch.from_numpy(obs)
        deltas = policy.member_deltas(n) if c["member_grad_stats"] else None
        self.optimizer.zero_grad(set_to_none=False)
        member_loss = torch.zeros(n, dtype=torch.float64)
        window_loss = torch.zeros(n, dtype=torch.float64)
        final_terms: dict[str, float] = {}
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            bar = tqdm(range(horizon), desc=f"apg epoch {self.epoch + 1} rollout", leave=False,
                       disable=not self.progress, unit="step")
            for t in bar:
                obs, reward, _, _, info = env.step_grad(policy(obs, deltas))
                window_loss = window_loss - reward
                if (t + 1) % window == 0 or t + 1 == horizon:
                    (window_loss.sum() / n).backward()
                    member_loss += window_loss.detach()
                    window_loss = torch.zeros(n, dtype=torch.float64)
                    obs = self._cut_graph(obs)
            final_terms = {k: float(np.mean(info[k])) for k in self.task.term_names}
            success = float(np.mean(info.get("success", [False])))
        adjoint_warnings = [str(w.message) for w in caught if "diffcloth gradient" in str(w.message)]
        for w in caught:
            if "diffcloth gradient" not in str(w.message):
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        stats = self._grad_stats(deltas, n)
        grad_norm = stats["grad_norm"]
        clipped, skipped = False, False
        if not math.isfinite(grad_norm):
            skipped = True  # no Adam step on a non-finite gradient; logged below
            tqdm.write(f"apg epoch {self.epoch + 1}: non-finite gradient norm {grad_norm}: Adam step skipped")
        else:
            clip = float(c["clip_grad_norm"])
            if clip > 0 and grad_norm > clip:
                torch.nn.utils.clip_grad_norm_(policy.parameters(), clip)
                clipped = True
                if self.clip_count == 0:
                    tqdm.write(f"apg: gradient norm {grad_norm:.3g} clipped to {clip} (logged per epoch in "
                               f"train.csv, column 'clipped')")
                self.clip_count += 1
            self.optimizer.step()
        if adjoint_warnings:
            tqdm.write(f"apg epoch {self.epoch + 1}: {len(adjoint_warnings)} adjoint warning(s), first: "
                       f"{adjoint_warnings[0]}")
        self.epoch += 1
        return {"epoch": self.epoch, "train_loss": float(member_loss.mean()),
                "train_loss_min": float(member_loss.min()), "train_loss_max": float(member_loss.max()),
                **{f"final_{k}": v for k, v in final_terms.items()}, "train_success": success,
                **stats, "clipped": clipped, "step_skipped": skipped, "adjoint_warnings": len(adjoint_warnings),
                **self.counter.snapshot()}

    def _cut_graph(self, obs: torch.Tensor) -> torch.Tensor:
        """Detaches the rollout's state between windows (the engine's graph and the
        observation); the next step's record starts from the same values without history."""
        self.engine.detach_graph()
        return obs.detach()

    def _grad_stats(self, deltas, n: int) -> dict[str, float]:
        g = torch.cat([p.grad.reshape(-1) for p in self.policy.parameters()])
        out = {"grad_norm": float(torch.linalg.vector_norm(g))}
        if deltas is not None:
            # delta_i's gradient is dL_i/dtheta / n (the loss is the batch mean).
            gi = n * torch.cat([d.grad.reshape(n, -1) for d in deltas], dim=1)
            norms = torch.linalg.vector_norm(gi, dim=1)
            out.update(member_grad_norm_mean=float(norms.mean()), member_grad_norm_max=float(norms.max()),
                       grad_variance=float(((gi - gi.mean(0)) ** 2).sum(1).mean()))
        return out

    # -- evaluation and the loop -------------------------------------------------------------------
    def evaluate(self, frames_every: int | None = None):
        if self._eval_env is None:
            self._eval_env = make_eval_env(self.cfg["env_id"], len(self.eval_starts), self.cfg["env"])
        return evaluate(self.policy, self.cfg["env_id"], self.eval_starts, env=self._eval_env,
                        frames_every=frames_every)

    def _eval_point(self) -> None:
        self.clock.start()
        ev = self.evaluate()
        self.clock.stop("eval")
        self.eval_steps += ev.steps
        point = {"epoch": self.epoch, "steps": self.counter.forward,
                 "paper_steps": paper_count("apg", self.epoch, self.task.horizon, self.counter.forward),
                 "backward_steps": self.counter.backward, "train_s": self.clock.train_s,
                 "test_loss": ev.mean_loss, "success_rate": ev.success_rate}
        self.curve.append(point)
        self.last_eval = ev.per_start()
        if self.eval_log is not None:
            self.eval_log.write(point)

    def train(self, epochs: int | None = None, deadline: float | None = None) -> dict[str, Any]:
        """Trains up to ``epochs`` in total (default the config's), evaluating every
        ``eval_every`` epochs and at the end; stops early (after a checkpoint, resumable) once
        ``time.time()`` passes ``deadline``. Returns the run's summary."""
        epochs = int(self.cfg["epochs"] if epochs is None else epochs)
        self.target_epochs = epochs
        every = int(self.cfg["eval_every"])
        if not self.curve:
            self._eval_point()
            self.save()
        bar = tqdm(total=epochs, initial=self.epoch, desc=f"apg seed {self.seed}", disable=not self.progress,
                   unit="epoch")
        while self.epoch < epochs and (deadline is None or time.time() < deadline):
            self.clock.start()
            row = self.run_epoch()
            row["epoch_s"] = self.clock.stop("train")
            if self.train_log is not None:
                self.train_log.write(row)
            out_of_time = deadline is not None and time.time() >= deadline
            if (every and self.epoch % every == 0) or self.epoch == epochs or out_of_time:
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
        return {"method": "apg", "seed": self.seed, "epochs": self.epoch, "budget_epochs": target,
                "complete": self.epoch >= target, "final_test_loss": last.get("test_loss"),
                "final_eval_epoch": last.get("epoch"), "per_start": self.last_eval,
                "success_rate": last.get("success_rate"), "curve": self.curve, **self.counter.snapshot(),
                "paper_steps": paper_count("apg", self.epoch, self.task.horizon, self.counter.forward),
                "eval_steps": self.eval_steps, "clipped_epochs": self.clip_count, **self.clock.state(),
                **threads()}


def train_apg(cfg: Mapping[str, Any] | None = None, run_dir: str | Path | None = None, seed: int = 0,
              **kwargs: Any) -> APGTrainer:
    """Trains (or resumes) an APG run; returns the trainer (its ``policy`` and ``summary()``)."""
    trainer = APGTrainer(cfg, run_dir, seed, **kwargs)
    trainer.train()
    return trainer
