"""The base class of every cloth env: a Gymnasium ``Env`` over a batch of one
(``engine.ClothEngine``), plus the differentiable ``step_grad``. A subclass names its task
(``task_class``) and carries the Gymnasium docstring; it holds no plumbing."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import torch

from diffcloth_gym.envs.engine import ClothEngine
from diffcloth_gym.envs.task import ClothTask
from diffcloth_gym.rendering import display_available


class ClothEnv(gym.Env):
    """A cloth task as a Gymnasium env. Arguments common to every cloth env:

    - ``render_mode``: None, ``"rgb_array"`` (an HxWx3 uint8 frame from a software rasterizer)
      or, where a display exists, ``"human"`` (a matplotlib window).
    - ``solver``: overrides of the scene's ``[solver]`` table (e.g. ``{"tolerance": 1e-9}``);
      plain and recorded steps share one tolerance (default ``engine.DEFAULT_TOLERANCE``) and
      one iteration cap (default ``engine.DEFAULT_MAX_ITERATIONS``).
    - ``threads``: run the simulator on a thread pool of its own with this many threads
      (default None: rayon's global pool, sized by ``RAYON_NUM_THREADS`` or the core count).
      The trajectory does not depend on it.
    - every key of the task's ``default_config()`` (see the env's docstring).
    """

    # "human" needs a window: advertised only where a display exists (headless checks of
    # every advertised mode would fail otherwise).
    metadata = {"render_modes": ["rgb_array"] + (["human"] if display_available() else []), "render_fps": 30}
    task_class: type[ClothTask]

    def __init__(self, render_mode: str | None = None, solver: dict | None = None, threads: int | None = None,
                 **task_overrides: Any):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']} or None, "
                             f"got {render_mode!r}")
        self.render_mode = render_mode
        self.engine = ClothEngine(self.task_class, 1, solver=solver, threads=threads, **task_overrides)
        self.task = self.engine.task
        bound = self.task.action_bound
        self.action_space = gym.spaces.Box(-bound, bound, (self.task.action_dim,), np.float64)
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (self.task.obs_dim,), np.float64)
        self._viewer = None

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Starts an episode: ``options={"start": spec}`` sets the start (see the env's
        Starting State), else one is drawn with the env's seeded generator."""
        super().reset(seed=seed)
        options = options or {}
        unknown = set(options) - {"start"}
        if unknown:
            raise ValueError(f"unknown reset option(s) {sorted(unknown)}; known: ['start']")
        start = self.task.start(options["start"]) if "start" in options else self.task.sample_start(self.np_random)
        return self.engine.reset([0], [start])[0], {}

    def step(self, action):
        r = self.engine.step(action)
        return r.obs[0], float(r.reward[0]), bool(r.terminated[0]), bool(r.truncated[0]), r.infos[0]

    def step_grad(self, action: torch.Tensor):
        """The same transition as ``step``, differentiable: ``action`` is a float64 torch
        tensor (action_dim,) that may require grad; returns ``(obs, reward, terminated,
        truncated, info)`` with ``obs`` and ``reward`` torch tensors whose graph runs through
        the simulator's adjoint (contact included). ``sum(rewards).backward()`` over an episode
        gives d(return)/d(whatever produced the actions). An episode uses ``step`` or
        ``step_grad``, not both (mixing raises ``InputError``). Memory: each step's record
        (45 kB for the Hat, 75 kB for the Sock) is kept until the next ``reset``."""
        obs, reward, r = self.engine.step_grad(action.reshape(1, -1) if isinstance(action, torch.Tensor) else action)
        return obs[0], reward[0], bool(r.terminated[0]), bool(r.truncated[0]), r.infos[0]

    def render(self):
        """``rgb_array``: the current state as a (480, 480, 3) uint8 frame (software rasterizer,
        headless; cloth red/ochre by side, obstacles grey, effectors green). ``human``: shows
        it in a matplotlib window (needs a display)."""
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array' to gym.make")
            return None
        from diffcloth_gym import rendering

        frame = rendering.render_member(self.engine, 0)
        if self.render_mode == "human":
            if self._viewer is None:
                self._viewer = rendering.HumanViewer(type(self).__name__, self.metadata["render_fps"])
            self._viewer.show(frame)
            return None
        return frame

    def close(self):
        if self._viewer is not None:
            self._viewer.close()
            self._viewer = None
