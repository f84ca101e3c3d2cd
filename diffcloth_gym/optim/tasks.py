"""Optimization tasks built from the shipped scenes: a simulator, a parameterization, a loss
and a horizon, ready for :class:`~diffcloth_gym.optim.Objective` and the drivers."""

from __future__ import annotations

from dataclasses import dataclass

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

    def objective(self, **kwargs) -> Objective:
        return Objective(self.sim, self.param, self.loss, self.steps, **kwargs)


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
    sim.set_solver(preset="gradient")
    inputs = param.inputs(truth.ravel(), steps)
    sim.reset()
    target = np.empty((steps, n, 3))
    for k in range(steps):
        sim.step(external_forces=inputs.forces[k])
        target[k] = sim.positions
    loss = TrajectoryMatch(target, squared=True, mean=True)
    return Task(f"napkin{resolution}x{resolution}", sim, param, loss, steps, truth.ravel())
