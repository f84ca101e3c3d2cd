"""One evaluation for every method: a policy (an APG torch module, an SB3 model, or any
callable obs -> action) on the env's fixed ``TEST_STARTS``, all starts in one batch, with
deterministic actions (SB3: the Gaussian's mean) and plain steps (no recording).

Per start it reports the episode loss (the sum over steps of the task's loss terms, i.e. minus
the return) and each term's sum, the final step's terms, ``success`` (the task's rule at the
episode end), and the final node positions (for pictures). The same policy, starts and env
settings give bitwise the same numbers (the batch is deterministic across thread counts; the
policy runs in float64 for APG and in SB3's float32 for PPO, on the same inputs).
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

import gymnasium as gym
import numpy as np
import torch


def test_starts(env_id: str) -> tuple:
    """The env module's ``TEST_STARTS`` (every DiffCloth env file defines them)."""
    module = gym.spec(env_id).entry_point.split(":")[0]
    return tuple(importlib.import_module(module).TEST_STARTS)


def as_policy(policy: Any) -> Callable[[np.ndarray], np.ndarray]:
    """obs (N, obs_dim) -> actions (N, act_dim), deterministic, without gradients."""
    if isinstance(policy, torch.nn.Module):
        def act(obs: np.ndarray) -> np.ndarray:
            with torch.no_grad():
                return policy(torch.from_numpy(obs)).numpy()
        return act
    if hasattr(policy, "predict"):
        return lambda obs: policy.predict(obs, deterministic=True)[0].astype(np.float64)
    if callable(policy):
        return policy
    raise TypeError(f"not a policy: {type(policy).__name__}")


@dataclass
class Evaluation:
    """One policy on a list of starts; ``per_start`` rows are JSON-ready."""

    starts: list
    loss: np.ndarray                      # (S,) episode loss per start
    terms: dict[str, np.ndarray]          # term -> (S,) summed over the episode
    final_terms: dict[str, np.ndarray]    # term -> (S,) at the last step
    success: np.ndarray                   # (S,) bool
    final_positions: np.ndarray           # (S, n, 3)
    frames: list[np.ndarray] = field(default_factory=list)  # positions (S, n, 3) every frames_every steps
    steps: int = 0                        # time steps simulated (all starts)

    @property
    def mean_loss(self) -> float:
        return float(self.loss.mean())

    @property
    def success_rate(self) -> float:
        return float(self.success.mean())

    def per_start(self) -> list[dict[str, Any]]:
        rows = []
        for i, s in enumerate(self.starts):
            rows.append({"start": list(map(float, s)), "loss": float(self.loss[i]),
                         "terms": {k: float(v[i]) for k, v in self.terms.items()},
                         "final_terms": {k: float(v[i]) for k, v in self.final_terms.items()},
                         "success": bool(self.success[i])})
        return rows

    def summary(self) -> dict[str, Any]:
        return {"test_loss": self.mean_loss, "success_rate": self.success_rate,
                "terms": {k: float(v.mean()) for k, v in self.terms.items()},
                "final_terms": {k: float(v.mean()) for k, v in self.final_terms.items()}}


def make_eval_env(env_id: str, num_starts: int, env_kwargs: Mapping[str, Any] | None = None):
    """The vector env evaluations run on (one member per start); reuse it across evaluations."""
    return gym.make_vec(env_id, num_envs=num_starts, **dict(env_kwargs or {}))


class Evaluator:
    """Evaluates the policies of one run on its starts, on one eval env built at first use."""

    def __init__(self, env_id: str, starts: Sequence, env_kwargs: Mapping[str, Any] | None = None):
        self.env_id, self.starts, self.env_kwargs = env_id, list(starts), dict(env_kwargs or {})
        self._env = None

    def __call__(self, policy: Any, frames_every: int | None = None) -> Evaluation:
        if self._env is None:
            self._env = make_eval_env(self.env_id, len(self.starts), self.env_kwargs)
        return evaluate(policy, self.env_id, self.starts, env=self._env, frames_every=frames_every)


def evaluate(policy: Any, env_id: str, starts: Sequence | None = None, env_kwargs: Mapping[str, Any] | None = None,
             env: Any = None, frames_every: int | None = None) -> Evaluation:
    """``policy`` from each of ``starts`` (default: every ``TEST_STARTS``) for one episode.
    ``env``: a vector env from ``make_eval_env`` with one member per start (built if None).
    ``frames_every``: keep every member's positions every that many steps (for a GIF)."""
    starts = list(test_starts(env_id) if starts is None else starts)
    env = env if env is not None else make_eval_env(env_id, len(starts), env_kwargs)
    if env.num_envs != len(starts):
        raise ValueError(f"the eval env has {env.num_envs} members for {len(starts)} starts")
    from diffcloth_gym.training.accounting import engine_of

    engine = engine_of(env)
    act = as_policy(policy)
    obs, _ = env.reset(options={"starts": starts})
    names = engine.task.term_names
    terms = {k: np.zeros(len(starts)) for k in names}
    final = {k: np.zeros(len(starts)) for k in names}
    frames = [engine.batch.positions().copy()] if frames_every else []
    success = np.zeros(len(starts), dtype=bool)
    steps = 0
    for t in range(engine.task.horizon):
        obs, _, _, truncated, info = env.step(act(obs))
        steps += len(starts)
        for k in names:
            final[k] = np.asarray(info[k], dtype=np.float64)
            terms[k] += final[k]
        if frames_every and ((t + 1) % frames_every == 0 or t + 1 == engine.task.horizon):
            frames.append(engine.batch.positions().copy())
        if "solver_error" in info:
            bad = np.flatnonzero(info.get("_solver_error", []))
            raise RuntimeError(f"evaluation: the solver failed on start(s) {bad.tolist()}: "
                               f"{[info['solver_error'][i] for i in bad]}")
        if truncated.all():
            success = np.asarray(info["success"], dtype=bool)
            break
    loss = sum(terms.values())
    return Evaluation(starts=starts, loss=loss, terms=terms, final_terms=final, success=success,
                      final_positions=engine.batch.positions().copy(), frames=frames, steps=steps)
