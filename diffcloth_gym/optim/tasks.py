"""Optimization tasks built from the shipped scenes: a simulator, a parameterization, a loss
and a horizon, ready for :class:`~diffcloth_gym.optim.Objective` and the drivers."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from diffcloth_gym.optim.forces import NodeForces
from diffcloth_gym.optim.losses import Loss, TrajectoryMatch
from diffcloth_gym.optim.objective import Objective
from diffcloth_gym.optim.parameterization import Parameterization
from diffcloth_gym.scenes import load_scene
from diffcloth_gym.simulator import Simulator


@dataclass
class Task:
    name: str
    sim: Simulator
    param: Parameterization
    loss: Loss
    steps: int
    #: The parameters that generated the target motion, when known (identification tasks).
    truth: np.ndarray | None = None
    #: The rollout's start (None: the rest shape, at rest).
    x0: np.ndarray | None = None
    v0: np.ndarray | None = None
    #: Task-specific readouts of a rollout's positions (N, n, 3), e.g. the dress's apex angle.
    measure: Callable[[np.ndarray], dict] | None = None
    #: How this task differs from the paper's (mesh, loss, target), for reports.
    notes: str = ""
    extra: dict = field(default_factory=dict)

    def objective(self, **kwargs) -> Objective:
        kwargs.setdefault("x0", self.x0)
        kwargs.setdefault("v0", self.v0)
        return Objective(self.sim, self.param, self.loss, self.steps, **kwargs)


def task_scene(name: str, **mesh) -> dict:
    """A shipped scene's config (:func:`~diffcloth_gym.scenes.load_scene`: a relative OBJ mesh
    path comes back absolute, so the dict builds from any working folder)."""
    return load_scene(name, **mesh)


def synthesize(sim: Simulator, param: Parameterization, theta, steps: int, x0=None, v0=None) -> np.ndarray:
    """The positions (steps, n, 3) of a rollout under ``theta`` at the ``gradient`` preset (the
    accuracy every objective evaluation runs at, so a perfect fit has loss 0): the target
    motion of an identification task."""
    sim.set_solver(preset="gradient")
    sim.set_recording(False)
    inp = param.inputs(np.asarray(theta, dtype=np.float64), steps)
    if inp.params:
        sim.set_params(**inp.params)
    sim.reset(x0, v0)
    out = np.empty((steps, sim.num_nodes, 3))
    for k in range(steps):
        sim.step(attachment_targets=None if inp.targets is None else inp.targets[k],
                 external_forces=None if inp.forces is None else inp.forces[k])
        out[k] = sim.positions
    return out


def flying_napkin(resolution: int = 10, steps: int = 50, bound: float = 10.0) -> Task:
    """The flying napkin of the paper's Fig. 4: ``resolution`` x ``resolution`` nodes (4, 5, 7,
    10: 48, 75, 147, 300 variables), one time-invariant force per node, matched to a reference
    motion (trajectory matching, mean squared node distance over every step and node: the
    reference code's ``MATCH_TRAJECTORY``).

    The forces are in units of the mean node's weight (``scale = m g``, so the numbers mean
    the same at every resolution) and bounded in ``[-bound, bound]`` per component (the
    reference code's constant force field bound is 10). The reference motion is the rollout
    under a known smooth field: a lift of 1.5 weights, a push of 0.5 along +x and +z, and a
    twist growing with the distance from the centre (the napkin flies up, sideways and turns);
    a perfect fit has loss 0. The paper's target motion is not in its public code.
    """
    cfg = load_scene("napkin", rows=resolution, cols=resolution)
    sim = Simulator.from_config(cfg)
    n = sim.num_nodes
    weight = float(np.mean(sim.masses)) * 9.8
    param = NodeForces(n, scale=weight, bound=bound)
    rest = sim.rest_positions
    r = rest - rest.mean(axis=0)
    truth = np.empty((n, 3))
    truth[:, 0] = 0.5 - 1.0 * r[:, 2]
    truth[:, 1] = 1.5
    truth[:, 2] = 0.5 + 1.0 * r[:, 0]
    target = synthesize(sim, param, truth.ravel(), steps)
    loss = TrajectoryMatch(target, squared=True, mean=True)
    return Task(f"napkin{resolution}x{resolution}", sim, param, loss, steps, truth.ravel())
