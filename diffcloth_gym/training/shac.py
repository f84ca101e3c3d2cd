"""Short-horizon actor-critic (SHAC, Xu et al. 2022, "Accelerated Policy Learning with Parallel
Differentiable Simulation"): analytic policy gradients through short windows of the simulator
plus a learned value for what lies beyond the window. Going beyond the paper's controller, in
the same harness (same env, policy, starts, evaluation and step accounting as APG and PPO).

Each epoch rolls out ``batch`` random starts in parallel for one whole episode, cut into
windows of ``window`` steps. Per window:

1. **Actor**: the window's return through ``step_grad``, bootstrapped by the target critic,

       J = 1/(n h) sum_i [ sum_{t<h} gamma^t r_t^i + gamma^h V'(s_h^i) ]

   (no bootstrap when the episode ends in the window: the env's episodes have a fixed
   length), is backpropagated through the simulator's adjoint and the policy; one Adam step
   on ``-J``, its gradient norm clipped at ``clip_grad_norm`` (logged per window, as APG).
2. **Critic**: TD(lambda) targets of the window's states from the target critic, fitted by
   ``critic_iterations`` passes of ``critic_minibatches`` mini-batches (MSE, Adam); the target
   critic then moves ``1 - target_alpha`` of the way to the critic (SHAC's soft update).
3. The state is detached (``EpochTrainer.cut_graph``) and the next window starts from it.

Rewards are multiplied by ``reward_scale`` for both the actor and the critic (the Hat's
per-step loss is a few units, its episode loss ~10^3); the logged losses are unscaled. The
critic sees the observation and the episode's elapsed fraction t/N (the env's episodes have a
fixed length, so the value depends on time; the policy's input stays the env's observation,
the same as APG's and PPO's).

Step accounting: every window's steps are forward steps (counted by the engine) and as many
one-step adjoints; the paper's count equals ours (env steps).
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import torch
from torch import nn
from tqdm.auto import tqdm

from diffcloth_gym.training.epochs import AdjointWarnings, EpochTrainer, epoch_seed

__all__ = ["Critic", "SHACTrainer", "td_lambda_targets", "train_shac"]


class Critic(nn.Module):
    """V(obs, t/N): an MLP with ELU activations (SHAC's), float64, seeded."""

    def __init__(self, obs_dim: int, hidden: Sequence[int] = (64, 64), seed: int = 0):
        super().__init__()
        sizes = [obs_dim + 1, *hidden, 1]
        layers: list[nn.Module] = []
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(seed)
            for k, (a, b) in enumerate(zip(sizes[:-1], sizes[1:])):
                layers.append(nn.Linear(a, b, dtype=torch.float64))
                if k < len(sizes) - 2:
                    layers.append(nn.ELU())
        self.net = nn.Sequential(*layers)

    def forward(self, obs: torch.Tensor, phase: torch.Tensor) -> torch.Tensor:
        phase = phase.to(obs.dtype).expand(obs.shape[:-1]).unsqueeze(-1)
        return self.net(torch.cat([obs, phase], dim=-1)).squeeze(-1)


def td_lambda_targets(rewards: torch.Tensor, next_values: torch.Tensor, gamma: float, lam: float,
                      episode_ends: bool) -> torch.Tensor:
    """TD(lambda) value targets of a window's states s_0..s_{h-1}: ``rewards[t]`` (h, n) is
    the reward of the step out of s_t, ``next_values[t]`` the target critic's V(s_{t+1}); when
    ``episode_ends`` the last step ends the episode (its next value is 0)::

        G_t = r_t + gamma ((1 - lam) V(s_{t+1}) + lam G_{t+1}),   G_{h-1} = r_{h-1} + gamma V(s_h)
    """
    h = rewards.shape[0]
    targets = torch.empty_like(rewards)
    nxt = next_values.clone()
    if episode_ends:
        nxt[-1] = 0.0
    g = nxt[-1]
    for t in reversed(range(h)):
        mix = nxt[t] if t == h - 1 else (1.0 - lam) * nxt[t] + lam * g
        g = rewards[t] + gamma * mix
        targets[t] = g
    return targets


class SHACTrainer(EpochTrainer):
    """One SHAC run in ``run_dir`` (resumed from its checkpoint when there is one)."""

    method = "shac"
    default_config = "hat_shac"

    def build(self) -> None:
        c = self.cfg
        self.critic = Critic(self.task.obs_dim, c["critic_hidden"], seed=self.seed + 7_919)
        self.target_critic = copy.deepcopy(self.critic).requires_grad_(False)
        self.critic_optimizer = torch.optim.Adam(self.critic.parameters(), lr=float(c["critic_lr"]))
        self.updates = 0

    def extra_state(self) -> dict[str, Any]:
        return {"critic": self.critic.state_dict(), "target_critic": self.target_critic.state_dict(),
                "critic_optimizer": self.critic_optimizer.state_dict(), "updates": self.updates}

    def load_extra_state(self, ck: Mapping[str, Any]) -> None:
        self.critic.load_state_dict(ck["critic"])
        self.target_critic.load_state_dict(ck["target_critic"])
        self.critic_optimizer.load_state_dict(ck["critic_optimizer"])
        self.updates = ck["updates"]

    # -- one epoch -------------------------------------------------------------------------------
    def run_epoch(self) -> dict[str, Any]:
        """One episode of the batch from this epoch's starts, one actor and critic update per
        window."""
        c, env = self.cfg, self.env
        n, horizon = int(c["batch"]), self.task.horizon
        window = int(c["window"])
        if window < 1:
            raise ValueError(f"shac: window must be >= 1 step, got {window}")
        obs, _ = env.reset(seed=epoch_seed(self.seed, self.epoch, n))
        obs = torch.from_numpy(obs)
        episode_loss = torch.zeros(n, dtype=torch.float64)
        rows: list[dict[str, float]] = []
        with AdjointWarnings(f"shac epoch {self.epoch + 1}") as adjoint:
            bar = tqdm(total=horizon, desc=f"shac epoch {self.epoch + 1} rollout", leave=False,
                       disable=not self.progress, unit="step")
            t = 0
            while t < horizon:
                steps = min(window, horizon - t)
                obs, row, rewards = self._window(obs, t, steps, horizon)
                episode_loss -= rewards.sum(0)
                rows.append(row)
                t += steps
                bar.update(steps)
                obs = self.cut_graph(obs)
            bar.close()
            info = self._last_info
            final_terms = {k: float(np.mean(info[k])) for k in self.task.term_names}
            success = float(np.mean(info.get("success", [False])))
        self.epoch += 1
        norms = [r["grad_norm"] for r in rows]
        return {"epoch": self.epoch, "train_loss": float(episode_loss.mean()),
                "train_loss_min": float(episode_loss.min()), "train_loss_max": float(episode_loss.max()),
                **{f"final_{k}": v for k, v in final_terms.items()}, "train_success": success,
                "grad_norm": float(np.mean(norms)), "grad_norm_max": float(np.max(norms)),
                "clipped": sum(r["clipped"] for r in rows), "step_skipped": sum(r["skipped"] for r in rows),
                "actor_updates": len(rows), "critic_loss": float(np.mean([r["critic_loss"] for r in rows])),
                "critic_loss_first_pass": float(np.mean([r["critic_loss_first_pass"] for r in rows])),
                "value_mean": float(np.mean([r["value_mean"] for r in rows])),
                "adjoint_warnings": len(adjoint.messages), **self.counter.snapshot()}

    def _window(self, obs: torch.Tensor, t0: int, steps: int, horizon: int):
        """One window from ``obs`` at step ``t0``: the actor's update, then the critic's.
        Returns the last observation (with its graph), the log row and the unscaled rewards."""
        c = self.cfg
        gamma, scale = float(c["gamma"]), float(c["reward_scale"])
        n = obs.shape[0]
        self.optimizer.zero_grad(set_to_none=False)
        states, rewards = [obs.detach()], []
        ret = torch.zeros(n, dtype=torch.float64)
        for j in range(steps):
            obs, reward, _, _, info = self.env.step_grad(self.policy(obs))
            ret = ret + gamma ** j * scale * reward
            rewards.append(reward.detach())
            states.append(obs.detach())
        ends = t0 + steps >= horizon
        if not ends:
            ret = ret + gamma ** steps * self.target_critic(obs, torch.tensor((t0 + steps) / horizon))
        (-ret.sum() / (n * steps)).backward()
        grad_norm = float(torch.linalg.vector_norm(torch.cat([p.grad.reshape(-1) for p in self.policy.parameters()])))
        clipped, skipped = self.clipped_step(self.optimizer, self.policy.parameters(), grad_norm,
                                             float(c["clip_grad_norm"]), "actor")
        self._last_info = info
        rewards_t = torch.stack(rewards)  # (steps, n)
        critic_first, critic_loss, value_mean = self._fit_critic(torch.stack(states), rewards_t * scale, t0, horizon, ends)
        self.updates += 1
        return obs, {"grad_norm": grad_norm, "clipped": clipped, "skipped": skipped, "critic_loss": critic_loss,
                     "critic_loss_first_pass": critic_first, "value_mean": value_mean}, rewards_t

    def _fit_critic(self, states: torch.Tensor, rewards: torch.Tensor, t0: int, horizon: int,
                    ends: bool) -> tuple[float, float, float]:
        """TD(lambda) targets from the target critic, then mini-batch regression; returns the
        first and the last pass's mean loss and the targets' mean."""
        c = self.cfg
        steps, n = rewards.shape
        phases = torch.arange(t0, t0 + steps + 1, dtype=torch.float64) / horizon  # of s_0..s_h
        with torch.no_grad():
            next_values = self.target_critic(states[1:], phases[1:, None])
            targets = td_lambda_targets(rewards, next_values, float(c["gamma"]), float(c["lam"]), ends)
        x, p, y = states[:-1].reshape(steps * n, -1), phases[:-1, None].expand(steps, n).reshape(-1), targets.reshape(-1)
        batches = max(1, min(int(c["critic_minibatches"]), len(y)))
        generator = torch.Generator().manual_seed(1_000_003 * self.seed + self.updates)
        passes = []
        for _ in range(int(c["critic_iterations"])):
            order = torch.randperm(len(y), generator=generator)
            losses = []
            for idx in order.chunk(batches):
                self.critic_optimizer.zero_grad(set_to_none=False)
                loss = ((self.critic(x[idx], p[idx]) - y[idx]) ** 2).mean()
                loss.backward()
                self.critic_optimizer.step()
                losses.append(loss.item())
            passes.append(float(np.mean(losses)))
        alpha = float(c["target_alpha"])
        with torch.no_grad():
            for tp, cp in zip(self.target_critic.parameters(), self.critic.parameters()):
                tp.mul_(alpha).add_(cp, alpha=1.0 - alpha)
        return passes[0], passes[-1], float(y.mean())


def train_shac(cfg: Mapping[str, Any] | None = None, run_dir: str | Path | None = None, seed: int = 0,
               **kwargs: Any) -> SHACTrainer:
    """Trains (or resumes) a SHAC run; returns the trainer (its ``policy`` and ``summary()``)."""
    trainer = SHACTrainer(cfg, run_dir, seed, **kwargs)
    trainer.train()
    return trainer
