"""Time-invariant per-node external forces (paper Sec. 5, Fig. 4: the flying napkin)."""

from __future__ import annotations

import numpy as np

from diffcloth_gym.optim.parameterization import Inputs, check_bounds


class NodeForces:
    """One constant force per node (3 numbers each, node order), held over the whole rollout.

    ``theta`` is in units of ``scale`` newtons (so the bounds ``[-bound, bound]`` per component
    are in the same units: the reference code bounds its constant force field in [-10, 10]).
    The gradient is ``scale * sum_n dL/df_n`` (the backward's ``external_forces`` summed over
    the steps). Needs the ``external_forces`` effect.
    """

    def __init__(self, num_nodes: int, scale: float = 1.0, bound: float = 10.0):
        self.n = int(num_nodes)
        self.scale = float(scale)
        self.size = 3 * self.n
        self.names = [f"force{i}_{c}" for i in range(self.n) for c in "xyz"]
        self._bounds = check_bounds("NodeForces", -bound, bound, self.size)

    @property
    def bounds(self):
        return self._bounds

    def forces(self, theta) -> np.ndarray:
        """(n, 3) forces in N."""
        return self.scale * np.asarray(theta, dtype=np.float64).reshape(self.n, 3)

    def inputs(self, theta, steps: int) -> Inputs:
        return Inputs(forces=np.broadcast_to(self.forces(theta), (steps, self.n, 3)))

    def chain(self, theta, grads: dict, steps: int) -> np.ndarray:
        g = grads["external_forces_constant"]
        return self.scale * np.asarray(g).reshape(-1)
