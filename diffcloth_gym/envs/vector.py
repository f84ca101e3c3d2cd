"""Vector envs over one batched engine (members stepped in parallel in Rust): a Gymnasium
``VectorEnv`` (``gym.make_vec(id, num_envs=N)``) and, in ``sb3.py``, a stable-baselines3
``VecEnv``. Adapters only: they convert and forward, the engine and the task hold the physics
and the reward.

Seeding: ``reset(seed=s)`` seeds member i with ``s + i`` (Gymnasium's convention), so member i
runs bitwise the episode a single env reset with seed ``s + i`` runs.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import torch
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv

from diffcloth_gym.envs.engine import ClothEngine, StepResult
from diffcloth_gym.envs.task import ClothTask


def seeded_generators(seed: int | list[int | None] | None, n: int) -> list[np.random.Generator]:
    """One generator per member: ``seed + i``, a list of seeds, or fresh entropy."""
    if seed is None or isinstance(seed, int):
        seeds = [None if seed is None else seed + i for i in range(n)]
    else:
        if len(seed) != n:
            raise ValueError(f"seed: one per env ({n}), got {len(seed)}")
        seeds = list(seed)
    return [seeding.np_random(s)[0] for s in seeds]


def vector_infos(r: StepResult, live: np.ndarray) -> dict[str, Any]:
    """Gymnasium's vector info dict of the members ``live`` (a bool mask): what
    ``VectorEnv._add_info`` builds from each live member's info dict (every key an array over
    the members, zero where absent, and a ``_key`` mask), made from the step's columns at
    once. Values of a key only some members have (solver errors, success) are grouped the
    same way, by the type of the first one."""
    infos: dict[str, Any] = {}
    for name, col in r.columns.items():
        infos[name] = np.where(live, col, np.zeros((), dtype=col.dtype))
        infos[f"_{name}"] = live.copy()
    for i, extra in sorted(r.extras.items()):
        if not live[i]:
            continue
        for key, value in extra.items():
            if key not in infos:
                known = type(value) in (int, float, bool)
                infos[key] = np.zeros(len(live), dtype=type(value)) if known \
                    else np.full(len(live), None, dtype=object)
                infos[f"_{key}"] = np.zeros(len(live), dtype=bool)
            infos[key][i] = value
            infos[f"_{key}"][i] = True
    return infos


class ClothVectorEnv(VectorEnv):
    """``num_envs`` members of a cloth task. Autoreset mode NEXT_STEP: the step after a member's
    episode ends resets it (its action is ignored; reward 0, not terminated, not truncated).
    ``step_grad`` needs the members in step (``reset()`` all together, no autoreset between).
    Arguments: those of the single env (``solver``, ``threads``, the task's; see ``ClothEnv``);
    ``threads`` sizes the pool the members are stepped on in parallel."""

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": ["rgb_array"]}
    task_class: type[ClothTask]

    def __init__(self, num_envs: int = 1, render_mode: str | None = None, solver: dict | None = None,
                 threads: int | None = None, **task_overrides: Any):
        self.engine = ClothEngine(self.task_class, num_envs, solver=solver, threads=threads, **task_overrides)
        self.task = self.engine.task
        self.num_envs = num_envs
        self.render_mode = render_mode
        bound = self.task.action_bound
        self.single_action_space = gym.spaces.Box(-bound, bound, (self.task.action_dim,), np.float64)
        self.single_observation_space = gym.spaces.Box(-np.inf, np.inf, (self.task.obs_dim,), np.float64)
        self.action_space = gym.vector.utils.batch_space(self.single_action_space, num_envs)
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space, num_envs)
        self._rngs = seeded_generators(None, num_envs)
        self._needs_reset = np.zeros(num_envs, dtype=bool)

    def reset(self, *, seed: int | list[int | None] | None = None, options: dict | None = None):
        """Resets every member. ``options={"starts": [spec, ...]}`` sets each member's start."""
        if seed is not None:
            self._rngs = seeded_generators(seed, self.num_envs)
        options = options or {}
        if "starts" in options:
            specs = list(options["starts"])
            if len(specs) != self.num_envs:
                raise ValueError(f"options['starts']: one per env ({self.num_envs}), got {len(specs)}")
            starts = [self.task.start(s) for s in specs]
        else:
            starts = [self.task.sample_start(rng) for rng in self._rngs]
        obs = self.engine.reset(list(range(self.num_envs)), starts)
        self._needs_reset[:] = False
        return obs, {}

    def step(self, actions):
        checked = self.engine.check_action(actions)
        done = np.flatnonzero(self._needs_reset)
        starts = [self.task.sample_start(self._rngs[i]) for i in done]
        if len(done) == self.num_envs:
            # Every member starts over: nothing to step.
            obs = self.engine.reset(done.tolist(), starts)
            self._needs_reset[:] = False
            zeros = np.zeros(self.num_envs, dtype=bool)
            return obs, np.zeros(self.num_envs), zeros, zeros.copy(), {}
        if len(done):
            # The batch steps every member in one call: the ones that start over are stepped
            # from their new start (a wasted step on a sane state) and put back to it below.
            self.engine.reset(done.tolist(), starts)
        r = self.engine.step(checked)
        obs, reward = r.obs, r.reward
        terminated, truncated = r.terminated.copy(), r.truncated.copy()
        if len(done):
            # NEXT_STEP: the step after an episode's end returns the new episode's first
            # observation; the action is ignored.
            obs[done] = self.engine.reset(done.tolist(), starts)
            reward[done], terminated[done], truncated[done] = 0.0, False, False
        live = np.ones(self.num_envs, dtype=bool)
        live[done] = False
        self._needs_reset = terminated | truncated
        return obs, reward, terminated, truncated, vector_infos(r, live)

    def step_grad(self, actions: torch.Tensor):
        """The batched differentiable step (see ``ClothEnv.step_grad``): ``actions`` (N,
        action_dim) float64 torch; returns obs (N, obs_dim) and rewards (N,) as tensors, and
        numpy terminated/truncated and the infos."""
        obs, reward, r = self.engine.step_grad(actions)
        return obs, reward, r.terminated, r.truncated, vector_infos(r, np.ones(self.num_envs, dtype=bool))

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        from diffcloth_gym import rendering

        return tuple(rendering.render_member(self.engine, i) for i in range(self.num_envs))
