"""Type stub of the Rust extension ``diffcloth_gym._core`` (rust/diffcloth-py).

Most callers want :class:`diffcloth_gym.Simulator`, the Python wrapper over this class.
Kept in sync with the binding by tests/test_core_stub.py. Errors raised are the classes in
:mod:`diffcloth_gym.errors`.
"""

from typing import Any

import numpy as np
import numpy.typing as npt

__version__: str
#: The differentiable physical parameters (the core's name table).
PARAM_NAMES: list[str]

class Simulator:
    """A cloth scene in the Rust core; arrays are float64 copies, one row per node."""

    @staticmethod
    def from_json(config_json: str, base_dir: str) -> Simulator:
        """Builds a simulator from a scene config in JSON; relative paths resolve against base_dir."""
    def reset(
        self,
        x: npt.NDArray[np.float64] | None = None,
        v: npt.NDArray[np.float64] | None = None,
    ) -> None:
        """Sets positions and velocities ((n, 3), default rest shape and zero), time 0; clears the tape."""
    def step(
        self,
        attachment_targets: npt.NDArray[np.float64] | None = None,
        external_forces: npt.NDArray[np.float64] | None = None,
        steps: int | None = None,
    ) -> dict[str, Any]:
        """Advances `steps` steps (None: 1) with the same inputs; returns the last step's stats."""
    @property
    def positions(self) -> npt.NDArray[np.float64]:
        """Node positions, (n, 3)."""
    @property
    def velocities(self) -> npt.NDArray[np.float64]:
        """Node velocities, (n, 3)."""
    @property
    def rest_positions(self) -> npt.NDArray[np.float64]:
        """Rest shape, (n, 3)."""
    @property
    def triangles(self) -> npt.NDArray[np.int64]:
        """Triangle node indices, (t, 3)."""
    @property
    def masses(self) -> list[float]:
        """Lumped node masses in kg, one per node."""
    @property
    def attachment_nodes(self) -> list[int]:
        """Indices of the attached nodes, in the order of attachment_targets."""
    @property
    def attachment_targets(self) -> npt.NDArray[np.float64]:
        """Current attachment targets, (k, 3)."""
    @property
    def handles(self) -> list[int]:
        """Suggested end-effector nodes of a garment mesh (empty otherwise)."""
    @property
    def effects(self) -> list[str]:
        """Names of the effects this scene simulates."""
    @property
    def time(self) -> float:
        """Simulated time since reset in seconds."""
    @time.setter
    def time(self, t: float) -> None:
        """Sets the simulated time (wind and moving obstacles depend on it)."""
    @property
    def step_count(self) -> int:
        """Steps taken since reset."""
    @property
    def num_nodes(self) -> int:
        """Number of mesh nodes n."""
    def params(self) -> dict[str, Any]:
        """Physical parameters: h, density, k_stretch, k_bend, k_attach, gravity, wind_*."""
    def set_params(self, **kwargs: Any) -> None:
        """Updates physical parameters by name; unknown names and bad values raise."""
    def solver(self) -> dict[str, Any]:
        """Solver settings: max_iterations, tolerance, acceleration, history, parallel, record_*."""
    def set_solver(self, **kwargs: Any) -> None:
        """Updates solver settings by name (the keys of solver())."""
    def profile(self) -> dict[str, float]:
        """Per-stage wall time (seconds) and counters accumulated since the last reset_profile()."""
    def reset_profile(self) -> None:
        """Zeroes the profile."""
    def last_step(self) -> dict[str, Any]:
        """Solver stats of the last step (as returned by step())."""
    def contacts(self) -> dict[str, Any]:
        """The last step's contacts as arrays: node_a, node_b, obstacle, normal, gap, mu, branch, impulse."""
    def overlap_warning(self) -> str | None:
        """A message if the state has nodes inside an obstacle or self-contact pairs closer than
        the radius (the first step throws them out), else None."""
    def obstacle_distance(self, index: int) -> list[float]:
        """Signed distance of every node to obstacle `index` at the current time."""
    def set_obstacle_mu(self, index: int, mu: float) -> None:
        """Sets the friction coefficient of obstacle `index`."""
    def set_self_mu(self, mu: float) -> None:
        """Sets the self-contact friction coefficient."""
    def set_recording(self, on: bool, checkpoint_every: int | None = None) -> None:
        """Starts (clearing the tape) or stops recording steps for backward(), optionally checkpointed."""
    def tape_info(self) -> tuple[int, int]:
        """(recorded steps, bytes held by the tape)."""
    def backward(
        self,
        dl_dx: npt.NDArray[np.float64] | None = None,
        dl_dv: npt.NDArray[np.float64] | None = None,
        solver: str | None = None,
        tolerance: float | None = None,
        max_iterations: int | None = None,
    ) -> dict[str, Any]:
        """Backpropagates (N, n, 3) dL/dx and dL/dv of the recorded steps; returns the gradients (None: the core's defaults: krylov, 1e-10, 500)."""
    def set_trace(self, on: bool) -> None:
        """Records (on) or stops recording (off) the PD convergence trace of each step."""
    def trace(self) -> npt.NDArray[np.float64]:
        """The last step's convergence trace, (iterations, 2): objective E and RMS PD update."""
    def mechanical_energy(self) -> float:
        """Kinetic + gravitational + elastic energy of the current state."""
    def principal_stretches(self) -> npt.NDArray[np.float64]:
        """Principal stretches (s1 >= s2) of every triangle, (t, 2)."""
    def write_obj(self, path: str) -> None:
        """Writes the current state as an OBJ file."""
