"""Type stub of the Rust extension ``diffcloth_gym._core`` (rust/diffcloth-py).

Most callers want :class:`diffcloth_gym.Simulator`, the Python wrapper over this class.
Kept in sync with the binding by tests/test_core_stub.py. Errors raised are the classes in
:mod:`diffcloth_gym.errors`.
"""

from typing import Any

import numpy as np
import numpy.typing as npt

__version__: str
#: The differentiable physical parameters (the core's name table, friction included).
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
        """Physical parameters by registry name: h, density, k_*, gravity, wind_*, mu_obstacles, mu_self."""
    def set_params(self, **kwargs: Any) -> None:
        """Updates physical parameters by name (friction included); bad names or values raise, nothing changes."""
    def solver(self) -> dict[str, Any]:
        """Solver settings of every step, recorded or not: max_iterations, tolerance, acceleration, history, parallel."""
    def set_solver(self, **kwargs: Any) -> None:
        """Updates solver settings by name (the keys of solver(), or preset="simulation" | "gradient" first)."""
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

class Batch:
    """N simulators sharing one model (one factorization), stepped in parallel; arrays carry the member index first."""

    def __init__(self, sim: Simulator, size: int, threads: int | None = None) -> None:
        """`size` simulators on `sim`'s model and solver settings, at the rest state, not recording;
        `threads`: a thread pool of the batch's own with that many threads (default rayon's global pool)."""
    def __len__(self) -> int:
        """Number of members."""
    @property
    def threads(self) -> int:
        """Threads a batched step runs on."""
    def reset(
        self,
        index: int,
        x: npt.NDArray[np.float64] | None = None,
        v: npt.NDArray[np.float64] | None = None,
    ) -> None:
        """Resets member `index` ((n, 3) arrays; default rest shape and zero velocity); clears its tape."""
    def set_recording(self, on: bool) -> None:
        """Starts (clearing the tapes) or stops recording on every member."""
    def step(
        self,
        attachment_targets: npt.NDArray[np.float64] | None = None,
        external_forces: npt.NDArray[np.float64] | None = None,
    ) -> list[Exception | None]:
        """One step of every member in parallel ((N, k, 3) targets, (N, n, 3) forces); per member None or the error it raised (not raised here)."""
    def positions(self) -> npt.NDArray[np.float64]:
        """Positions of every member, (N, n, 3)."""
    def velocities(self) -> npt.NDArray[np.float64]:
        """Velocities of every member, (N, n, 3)."""
    def attachment_targets(self) -> npt.NDArray[np.float64]:
        """Attachment targets in effect of every member, (N, k, 3)."""
    def step_counts(self) -> list[int]:
        """Steps taken since each member's reset."""
    def tape_info(self) -> list[tuple[int, int]]:
        """(recorded steps, bytes held) of each member's tape ((0, 0) when not recording)."""
    def last_steps(self) -> list[dict[str, Any]]:
        """The last step's solver stats of each member."""
    def last_stats(self) -> dict[str, npt.NDArray[Any]]:
        """The last step's solver stats of every member as arrays: ``iterations`` (N,) int64,
        ``residual`` (N,) float64, ``converged`` (N,) bool."""
    def profile(self, index: int) -> dict[str, Any]:
        """The profile (times, iteration and contact counts) of member `index`."""
    def backward_step(
        self,
        step: int,
        dl_dx: npt.NDArray[np.float64],
        dl_dv: npt.NDArray[np.float64],
        solver: str | None = None,
        tolerance: float | None = None,
        max_iterations: int | None = None,
    ) -> dict[str, Any]:
        """One-step adjoint of recorded step `step` on every member: gradients on its inputs (x, v, attachment_targets, external_forces) and warnings."""

class Renderer:
    """Software renderer (rust/diffcloth-render) of a fixed frame size; holds its buffers across frames."""

    def __init__(self, width: int, height: int) -> None:
        """A renderer of width x height pixels (each 1..=4096), reused across frames."""
    @property
    def width(self) -> int:
        """Frame width in pixels."""
    @property
    def height(self) -> int:
        """Frame height in pixels."""
    def render(self, sim: Simulator, camera: dict[str, Any] | None = None) -> npt.NDArray[np.uint8]:
        """The simulator's current state as an (height, width, 3) uint8 RGB frame."""
    def render_member(self, batch: Batch, index: int, camera: dict[str, Any] | None = None) -> npt.NDArray[np.uint8]:
        """Member `index` of a batch as an (height, width, 3) uint8 RGB frame (the envs' frames)."""
    def default_camera(self, sim: Simulator) -> dict[str, Any]:
        """The default camera for a simulator's scene: {"eye", "target", "up", "fov"}."""
