"""What a cloth task adds to a scene: its start states, how an action drives the cloth, what
the agent observes and what the loss is. The env base class (``base.py``) does the plumbing
(simulator batch, reset, step, ``step_grad``, rendering); a task holds no simulator state.

Every function that feeds the reward or the observation takes and returns float64 torch
tensors with a leading batch dimension ``B``, so one implementation serves the plain step
(under ``torch.no_grad``), the vector env (``B = num_envs``) and the differentiable
``step_grad`` (the graph runs from the loss back through ``control`` into the actions).

Shapes: ``x``, ``v`` (B, n, 3) node positions and velocities after the step; ``control``
(B, k, 3) the task's control state (end-effector positions for tasks that drive attachments;
k = 0 for force-driven tasks); ``action`` (B, action_dim).
"""

from __future__ import annotations

import abc
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np
import torch


@dataclass(frozen=True)
class Start:
    """One episode's start: cloth positions and velocities (n, 3) and the control state (k, 3)."""

    x: np.ndarray
    v: np.ndarray
    control: np.ndarray


@dataclass(frozen=True)
class Drive:
    """What the simulator receives for one step (batched): attachment targets (B, k, 3) or
    None, external forces (B, n, 3) or None."""

    targets: torch.Tensor | None
    forces: torch.Tensor | None


class ClothTask(abc.ABC):
    """A task on one scene. Subclasses set the class attributes and implement the methods.

    ``scene`` names a config in ``diffcloth_gym/configs`` (the physics); the task's own
    arguments (start ranges, loss weights, action scale) come from ``default_config()`` plus
    the overrides given to ``gym.make``."""

    #: Scene config name (``diffcloth_gym.scenes.load_config``).
    scene: str
    #: Names of the loss terms returned by ``loss_terms`` (reported in ``info``).
    term_names: tuple[str, ...]

    @classmethod
    def default_config(cls) -> dict[str, Any]:
        """The task's arguments and their defaults (documented in the env's docstring)."""
        return {}

    #: Solver settings the env uses unless its ``solver`` argument says otherwise (e.g. a
    #: polish the task's scene converges badly without); the tolerance is the engine's.
    solver_defaults: dict[str, Any] = {}

    @classmethod
    def scene_overrides(cls, config: Mapping[str, Any]) -> dict[str, Any]:
        """Changes to the scene config that the task's arguments ask for (e.g. a mesh
        resolution), as ``{table: {key: value}}`` merged into the loaded scene."""
        return {}

    def __init__(self, scene: Mapping[str, Any], rest_positions: np.ndarray, handles: list[int],
                 config: Mapping[str, Any]):
        """``scene``: the loaded scene config (dict); ``rest_positions`` (n, 3) the cloth as the
        scene builds it; ``handles``: the attached nodes in attachment order."""

    #: Episode length in steps (truncation).
    horizon: int
    #: Action dimension; the action space is Box(-action_bound, action_bound, (action_dim,)).
    action_dim: int
    action_bound: float
    #: Observation dimension.
    obs_dim: int

    @abc.abstractmethod
    def sample_start(self, rng: np.random.Generator) -> Start:
        """A random start (``reset(seed=...)``)."""

    def probe_start(self) -> Start:
        """The start of the short episode that fingerprints a training run's dynamics
        (``training.runlog.dynamics_probe``): one that reaches the task's contacts early
        where the task's random starts do not. Default: the random start of seed 0."""
        return self.sample_start(np.random.default_rng(0))

    @abc.abstractmethod
    def start(self, spec: Any) -> Start:
        """The start named by ``reset(options={"start": spec})``; raises ``InputError`` for a
        bad spec."""

    @abc.abstractmethod
    def drive(self, control: torch.Tensor, action: torch.Tensor) -> tuple[torch.Tensor, Drive]:
        """Applies an action (already checked and clipped): returns the new control state and
        what the simulator gets for this step. Differentiable in ``action`` and ``control``."""

    @abc.abstractmethod
    def observe(self, x: torch.Tensor, v: torch.Tensor, control: torch.Tensor) -> torch.Tensor:
        """The observation (B, obs_dim) of the state after a step (or the start)."""

    @abc.abstractmethod
    def loss_terms(self, x: torch.Tensor, v: torch.Tensor, control: torch.Tensor,
                   step: int) -> dict[str, torch.Tensor]:
        """This step's share of the episode loss, per term, each (B,); ``step`` counts from 1
        (the state after the first step). The reward is minus their sum."""

    @abc.abstractmethod
    def success(self, x: torch.Tensor, v: torch.Tensor, control: torch.Tensor) -> torch.Tensor:
        """Whether the final state counts as success, (B,) bool (reported at the episode end)."""
