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

Starts, checkpoints (every epoch), evaluation and the loop: ``epochs.EpochTrainer``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

import numpy as np
import torch
from tqdm.auto import tqdm

from diffcloth_gym.training.epochs import AdjointWarnings, EpochTrainer, epoch_seed

__all__ = ["APGTrainer", "epoch_seed", "train_apg"]


class APGTrainer(EpochTrainer):
    """One APG run in ``run_dir`` (resumed from its checkpoint when there is one)."""

    method = "apg"
    default_config = "hat_apg"

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
        with AdjointWarnings(f"apg epoch {self.epoch + 1}") as adjoint:
            bar = tqdm(range(horizon), desc=f"apg epoch {self.epoch + 1} rollout", leave=False,
                       disable=not self.progress, unit="step")
            for t in bar:
                obs, reward, _, _, info = env.step_grad(policy(obs, deltas))
                window_loss = window_loss - reward
                if (t + 1) % window == 0 or t + 1 == horizon:
                    (window_loss.sum() / n).backward()
                    member_loss += window_loss.detach()
                    window_loss = torch.zeros(n, dtype=torch.float64)
                    obs = self.cut_graph(obs)
            final_terms = {k: float(np.mean(info[k])) for k in self.task.term_names}
            success = float(np.mean(info.get("success", [False])))
        stats = self._grad_stats(deltas, n)
        clipped, skipped = self.clipped_step(self.optimizer, policy.parameters(), stats["grad_norm"],
                                             float(c["clip_grad_norm"]), "policy")
        self.epoch += 1
        return {"epoch": self.epoch, "train_loss": float(member_loss.mean()),
                "train_loss_min": float(member_loss.min()), "train_loss_max": float(member_loss.max()),
                **{f"final_{k}": v for k, v in final_terms.items()}, "train_success": success,
                **stats, "clipped": clipped, "step_skipped": skipped, "adjoint_warnings": len(adjoint.messages),
                **self.counter.snapshot()}

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


def train_apg(cfg: Mapping[str, Any] | None = None, run_dir: str | Path | None = None, seed: int = 0,
              **kwargs: Any) -> APGTrainer:
    """Trains (or resumes) an APG run; returns the trainer (its ``policy`` and ``summary()``)."""
    trainer = APGTrainer(cfg, run_dir, seed, **kwargs)
    trainer.train()
    return trainer
