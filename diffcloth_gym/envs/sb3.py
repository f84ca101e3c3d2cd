"""A stable-baselines3 ``VecEnv`` over the batched engine, so ``PPO("MlpPolicy", adapter)``
trains on it directly (SB3 cannot consume a Gymnasium ``VectorEnv``). SB3's conventions: a
member whose episode ends is reset in the same step, its last observation goes to
``infos[i]["terminal_observation"]``, and ``infos[i]["TimeLimit.truncated"]`` says the end was
a time limit. Seeds: ``seed(s)`` makes the next reset seed member i with ``s + i``, as the
Gymnasium vector env does."""

from __future__ import annotations

from typing import Any, Iterable

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env import VecEnv

from diffcloth_gym.envs.engine import ClothEngine
from diffcloth_gym.envs.vector import seeded_generators


class ClothSB3VecEnv(VecEnv):
    """``env_id``'s task on ``num_envs`` members of one batch (any registered DiffCloth id);
    ``**kwargs`` as for ``gym.make`` (task arguments, ``solver``)."""

    def __init__(self, env_id: str, num_envs: int = 1, render_mode: str | None = None, **kwargs: Any):
        spec = gym.spec(env_id)
        task_class = gym.envs.registration.load_env_creator(spec.entry_point).task_class
        self.engine = ClothEngine(task_class, num_envs, **{**spec.kwargs, **kwargs})
        self.task = self.engine.task
        self.render_mode = render_mode
        bound = self.task.action_bound
        super().__init__(num_envs,
                         gym.spaces.Box(-np.inf, np.inf, (self.task.obs_dim,), np.float64),
                         gym.spaces.Box(-bound, bound, (self.task.action_dim,), np.float64))
        self._rngs = seeded_generators(None, num_envs)
        self._actions: np.ndarray | None = None

    def reset(self) -> np.ndarray:
        if any(s is not None for s in self._seeds):
            self._rngs = seeded_generators(self._seeds, self.num_envs)
        self._reset_seeds()
        self._reset_options()
        starts = [self.task.sample_start(rng) for rng in self._rngs]
        return self.engine.reset(list(range(self.num_envs)), starts).astype(np.float64)

    def seed(self, seed: int | None = None):
        if seed is None:
            return super().seed(seed)
        self._seeds = [seed + i for i in range(self.num_envs)]
        return self._seeds

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self):
        r = self.engine.step(self._actions)
        obs, dones = r.obs, r.terminated | r.truncated
        infos = r.infos
        done = np.flatnonzero(dones)
        if len(done):
            for i in done:
                infos[i]["terminal_observation"] = obs[i].copy()
                infos[i]["TimeLimit.truncated"] = bool(r.truncated[i] and not r.terminated[i])
            obs[done] = self.engine.reset(done.tolist(), [self.task.sample_start(self._rngs[i]) for i in done])
        return obs, r.reward.astype(np.float32), dones, infos

    def close(self) -> None:
        pass

    def _indices(self, indices: None | int | Iterable[int]) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        return [indices] if isinstance(indices, int) else list(indices)

    def get_attr(self, attr_name: str, indices=None) -> list[Any]:
        # Members share one task and engine: attributes are the adapter's own.
        return [getattr(self, attr_name) for _ in self._indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        setattr(self, attr_name, value)

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs) -> list[Any]:
        return [getattr(self, method_name)(*method_args, **method_kwargs) for _ in self._indices(indices)]

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        return [False for _ in self._indices(indices)]

    def get_images(self):
        from diffcloth_gym import rendering

        return [rendering.render_member(self.engine, i) for i in range(self.num_envs)]
