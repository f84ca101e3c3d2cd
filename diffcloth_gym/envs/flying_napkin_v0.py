"""FlyingNapkin-v0: per-node external forces fly a napkin to a target pose (DiffCloth, Li et
al. 2022, Sec. 5.2 and Fig. 4).

## Description

A square napkin (the `napkin` scene, `diffcloth_gym/configs/napkin.toml`: 2 x 2 units,
horizontal at height 2, density 0.2, k_stretch 200, k_bend 0.05, strain limits [0.95, 1.05],
gravity, h = 0.01 s) of `resolution` x `resolution` nodes (default 10: 100 nodes) is moved by
an external force on every node. There is no attachment, no obstacle and no contact: the scene
declares no contact effect, so collision detection never runs (its profile shows zero
detection and contact time). The goal is to bring the napkin into a target pose: the rest shape
turned by `target_rotate_deg` about its centre and moved by `target_offset` (default: turned
45 degrees about the vertical, 1 unit up and 1.5 units along +z).

The paper's experiment optimizes time-invariant per-node forces (48 to 300 variables for 4x4
to 10x10 nodes) so that the cloth ends at a target position, comparing L-BFGS-B with CMA-ES;
the reference code parametrizes such forces as a constant force field bounded in [-10, 10]
per component (`omegaiota/DiffCloth`, `src/code/optimization/OptimizeHelper.cpp`,
`dL_dconstantForceField`) and measures position discrepancy as a mean squared node distance
(`src/code/simulation/Simulation.cpp`, `calculateLossAndGradient`, `MATCH_TRAJECTORY`). The
flying-napkin scene itself is not in the public reference code; the target pose here is our
choice. As an env the forces may change every step (the paper's constant forces are the
special case of a constant action).

`scene_overrides(config)` gives the scene's `[mesh]` rows and cols for `resolution`; the env
builds the scene with them.

## Action Space

`Box(-1, 1, (3 r^2,), float64)` (48 for r = 4, 300 for r = 10): the force on each node (node
order of the grid, x, y, z per node) as a fraction of `max_force`. The force in N on a node is
`max_force * action`, with `max_force = max_accel * m` where `m` is the mean node mass (total
mass density x width x height = 0.8 kg, over r^2 nodes): with the default `max_accel` = 20
units/s^2 that is 0.16 N per node at r = 10 and 1.0 N at r = 4 (gravity on a mean node is
0.078 N at r = 10). Lumped node masses follow the triangulation (they span a factor 8, the
lightest at corners; `Simulator.masses` gives them), so the same force accelerates light nodes
more.

## Observation Space

`Box(-inf, inf, (6 r^2,), float64)` (n = r^2 nodes):

| slice | what |
|---|---|
| `[0, 3n)` | node positions minus the target pose, n x (x, y, z) |
| `[3n, 6n)` | node velocities, n x (x, y, z) |

## Rewards

The loss is the mean squared node distance to the target pose, `distance = mean_i |x_i -
x*_i|^2` (units^2; the reference's position discrepancy), reported in `info` as the one term
`distance`. With `reward = "dense"` (default) every step gets `-distance / N` (the return is
minus the time-average over the episode: flying there early pays); with `reward = "final"`
only the last step gets `-distance` (the paper's goal: the cloth ends at the target).

## Starting State

The rest shape moved by `(dx, dy, dz)`, at rest. `reset(seed=...)` draws each of dx, dy, dz
uniformly in `[-start_offset, start_offset]` (default 0.25 units); `reset(options={"start":
(dx, dy, dz)})` sets one (out of range raises `InputError`);
`diffcloth_gym.envs.flying_napkin_v0.TEST_STARTS` holds 20 fixed starts spread over the default
range (the first 20 points of the Halton sequence in bases 2, 3, 5).

## Episode End

Truncated after the scene's `steps` (100 steps, 1 s); never terminated. `info["success"]` at
the end: the mean node distance to the target pose (not squared) below `success_distance`
(default 0.1 units, 5 % of the napkin's side).

## Arguments

| argument | default | meaning |
|---|---|---|
| `resolution` | 10 | nodes per side (r x r nodes, r >= 2; the paper uses 4, 5, 7, 10) |
| `max_accel` | 20.0 | full-scale force per node over the mean node mass, units/s^2 |
| `target_offset` | `[0.0, 1.0, 1.5]` | target translation of the rest shape's centre, units |
| `target_rotate_deg` | `[0.0, 45.0, 0.0]` | target rotation about the rest shape's centre, degrees about x, then y, then z (the scene placement's convention) |
| `start_offset` | 0.25 | random start offset range per axis, units |
| `reward` | `"dense"` | `"dense"` (every step's distance / N) or `"final"` (the last step's distance) |
| `success_distance` | 0.1 | success: final mean node distance below this, units |

## Version History

- v0: initial version.
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np
import torch

from ..errors import ConfigError, InputError
from ._common import halton, merge_config, number, rotation, start_values, vector3
from .base import ClothEnv
from .task import ClothTask, Drive, Start
from .vector import ClothVectorEnv

_DEFAULTS: dict[str, Any] = {
    "resolution": 10,
    "max_accel": 20.0,
    "target_offset": [0.0, 1.0, 1.5],
    "target_rotate_deg": [0.0, 45.0, 0.0],
    "start_offset": 0.25,
    "reward": "dense",
    "success_distance": 0.1,
}


def _test_starts() -> tuple[tuple[float, float, float], ...]:
    a = _DEFAULTS["start_offset"]
    return tuple(tuple(round(-a + 2 * a * halton(i, b), 4) for b in (2, 3, 5)) for i in range(1, 21))


#: 20 fixed starts ``(dx, dy, dz)`` spread over the default start range (Halton points in bases
#: 2, 3, 5), for evaluation: ``reset(options={"start": TEST_STARTS[i]})``.
TEST_STARTS = _test_starts()


def _resolution(cfg: Mapping[str, Any]) -> int:
    r = cfg["resolution"]
    if isinstance(r, bool) or not isinstance(r, (int, np.integer)) or r < 2:
        raise ConfigError(f"resolution must be an integer >= 2, got {r!r}")
    return int(r)


class FlyingNapkinTask(ClothTask):
    """FlyingNapkin-v0's task: per-node forces, distance to a target pose (see the module
    docstring)."""

    scene = "napkin"
    term_names = ("distance",)

    @classmethod
    def default_config(cls) -> dict[str, Any]:
        return {k: (list(v) if isinstance(v, list) else v) for k, v in _DEFAULTS.items()}

    @classmethod
    def scene_overrides(cls, config: Mapping[str, Any] | None) -> dict[str, Any]:
        """Overrides of the scene config for the task's arguments: the grid's resolution,
        ``{"mesh": {"rows": r, "cols": r}}``."""
        r = _resolution(merge_config(_DEFAULTS, config, "FlyingNapkin-v0"))
        return {"mesh": {"rows": r, "cols": r}}

    def __init__(self, scene: Mapping[str, Any], rest_positions: np.ndarray, handles: list[int],
                 config: Mapping[str, Any]):
        cfg = merge_config(_DEFAULTS, config, "FlyingNapkin-v0")
        self.config = cfg
        r = _resolution(cfg)
        rest = np.asarray(rest_positions, dtype=np.float64)
        n = rest.shape[0]
        if n != r * r:
            raise ConfigError(f"FlyingNapkin-v0: the scene has {n} nodes, resolution {r} needs {r * r} "
                              "(build the scene with scene_overrides(config))")
        if "external_forces" not in scene.get("effects", []):
            raise ConfigError("FlyingNapkin-v0 needs the scene effect 'external_forces'")
        mesh, material = scene.get("mesh", {}), scene.get("material", {})
        try:
            total_mass = float(material["density"]) * float(mesh["width"]) * float(mesh["height"])
        except (KeyError, TypeError, ValueError):
            raise ConfigError("FlyingNapkin-v0 needs a grid mesh (width, height) and material.density") from None
        self.max_force = number(cfg, "max_accel", 0.0, open_lo=True) * total_mass / n
        offset = vector3(cfg, "target_offset")
        R = rotation(vector3(cfg, "target_rotate_deg"))
        self.start_offset = number(cfg, "start_offset", 0.0)
        if cfg["reward"] not in ("dense", "final"):
            raise ConfigError(f"reward must be 'dense' or 'final', got {cfg['reward']!r}")
        self.dense = cfg["reward"] == "dense"
        self.success_distance = number(cfg, "success_distance", 0.0, open_lo=True)

        self.resolution = r
        self.horizon = int(scene.get("steps", 100))
        self.action_dim = 3 * n
        self.action_bound = 1.0
        self.obs_dim = 6 * n
        self.rest = rest
        centre = rest.mean(axis=0)
        self.target = (rest - centre) @ R.T + centre + offset
        self._target = torch.tensor(self.target, dtype=torch.float64)

    # -- starts ----------------------------------------------------------------------------
    def sample_start(self, rng: np.random.Generator) -> Start:
        d = rng.uniform(-self.start_offset, self.start_offset, size=3)
        return self.start(tuple(float(s) for s in d))

    def start(self, spec: Any) -> Start:
        d = np.array(start_values(spec, ("dx", "dy", "dz")))
        if np.any(np.abs(d) > self.start_offset + 1e-9):
            raise InputError(f"start {tuple(d.tolist())} is out of range: each of dx, dy, dz in "
                             f"[-{self.start_offset}, {self.start_offset}]")
        x = self.rest + d
        return Start(x=x, v=np.zeros_like(x), control=np.zeros((0, 3)))

    # -- dynamics, observation, loss ---------------------------------------------------------
    def drive(self, control: torch.Tensor, action: torch.Tensor) -> tuple[torch.Tensor, Drive]:
        forces = self.max_force * action.reshape(action.shape[0], -1, 3)
        return control, Drive(targets=None, forces=forces)

    def observe(self, x: torch.Tensor, v: torch.Tensor, control: torch.Tensor) -> torch.Tensor:
        B = x.shape[0]
        return torch.cat([(x - self._target.to(x)).reshape(B, -1), v.reshape(B, -1)], dim=1)

    def mean_squared_distance(self, x: torch.Tensor) -> torch.Tensor:
        """Mean squared node distance to the target pose, (B,)."""
        q = (x - self._target.to(x)) ** 2
        # x + y + z spelled out: bitwise torch's .sum(dim=-1) over the 3 components, and 6x
        # faster on (32, 100, 3) (a reduction kernel over a size-3 axis costs ~0.1 ms, as much
        # as the rest of the step's Python, which runs serially between parallel steps).
        return (q[..., 0] + q[..., 1] + q[..., 2]).mean(dim=-1)

    def loss_terms(self, x: torch.Tensor, v: torch.Tensor, control: torch.Tensor,
                   step: int) -> dict[str, torch.Tensor]:
        step = int(step)
        if self.dense:
            w = 1.0 / self.horizon if 1 <= step <= self.horizon else 0.0
        else:
            w = 1.0 if step == self.horizon else 0.0
        return {"distance": w * self.mean_squared_distance(x)}

    def success(self, x: torch.Tensor, v: torch.Tensor, control: torch.Tensor) -> torch.Tensor:
        d = torch.linalg.vector_norm(x - self._target.to(x), dim=-1).mean(dim=-1)
        return d < self.success_distance


class FlyingNapkinEnv(ClothEnv):
    task_class = FlyingNapkinTask


class FlyingNapkinVectorEnv(ClothVectorEnv):
    task_class = FlyingNapkinTask


# The env's documentation is this module's (Gymnasium's sections, above).
FlyingNapkinEnv.__doc__ = FlyingNapkinVectorEnv.__doc__ = __doc__
