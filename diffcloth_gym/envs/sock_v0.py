"""Sock-v0: four end effectors pull a sock onto a foot (DiffCloth, Li et al. 2022, Sec. 6.2
and Appendix B.2).

## Description

The procedural sock of the `sock` scene (1044 nodes, `diffcloth_gym/configs/sock.toml`) is
held at four nodes of its opening rim (the scene's handles, at +x, +z, -x and -z of the
opening as worn) by four end effectors. A foot and a leg (two capsules of radius 0.8 meeting
at the heel, the foot along +z, the leg along +y) are fixed obstacles; the sock starts in front
of the toes. The effectors must first hook the opening over the tip of the foot, then slide the
sock along the foot and up the leg. Frictional contact with the foot and leg (mu 0.1) and
self-collision are simulated; h = 1/160 s, 400 steps (2.5 s), as the reference.

The loss is the paper's keypoint loss (Eq. 33): distances between points on the foot model
and keypoint groups on the sock, evaluated halfway (the "hook" stage: the opening around the
tip of the foot) and at the end (the "wear" stage: the sock on the foot). The keypoint pairs
follow the reference implementation (`omegaiota/DiffCloth`,
`src/code/optimization/OptimizationTaskSetup.cpp`, `setLossFunctionInformationAndType`, case
`DEMO_WEAR_SOCK`): 8 wear pairs (heel, toe, instep, the four sides of the leg top, calf) and 4
hook pairs (toe tip <- opening front, sole at the tip <- opening back, the two sides of the tip
<- the opening's sides).

Keypoint groups are chosen by a geometric rule, not by hand: the sock's rest shape is the worn
shape (`rust/diffcloth/src/mesh/garment.rs` builds it around the two capsules; the scene's
`placement` moves it in front of the toes, and undoing the placement gives it back). Each wear
landmark is a point on the capsules' surface, in the frame of the leg axis ("up", from the
heel joint to the leg top), the foot axis ("forward", from the joint to the toe end) and
"side" = up x forward:

| keypoint | landmark on the foot model |
|---|---|
| `heel` | joint - r up (under the heel) |
| `toe` | toe end + r forward (the tip of the foot) |
| `instep` | joint + 0.5 L_foot forward + r up |
| `top_front`, `top_back` | leg top +- r forward |
| `top_side_pos`, `top_side_neg` | leg top +- r side |
| `calf` | joint + 0.4 L_leg up - r forward |

(`r`: capsule radius, `L`: capsule segment length; the reference's definitions, its
`getTransformedPosFromJointBindPos` calls.) A wear keypoint's group is the `keypoint_nodes`
sock nodes nearest to its landmark in the worn shape, and its target is where that group's
centroid is when the sock is worn (so the worn sock has zero wear loss). The hook stage reuses
the four opening groups (`top_front`, `top_back`, `top_side_pos`, `top_side_neg`) with targets
on the tip of the foot: toe end + (r + c) forward, toe end - (r + c) up, toe end +- (r + c) side,
where c = 0.1 is the sock's clearance (the worn opening's radius minus the leg's radius).

Differences from the reference, on purpose: a keypoint's distance is from its group's
centroid (the reference takes the farthest node of the group, squared, divided by the number
of pairs; the paper's Eq. 33 writes the plain L2 distance of a point); the hook stage is at
step N/2 as in the paper (the reference code uses 0.62 N, counted three times).

## Action Space

`Box(-1, 1, (12,), float64)`: for each effector in handle order (+x, +z, -x, -z rim node of
the worn sock) a displacement (x, y, z). The new effector position is the previous one plus
`action_scale * action` (scene length units; default 0.05 per step, i.e. at most 8 units/s per
axis at h = 1/160 s: 10 units per axis in each half of the episode, while the opening's path
from the start down to the tip of the foot and then back along the foot and up the leg needs
about 5.4 down and 1.7 back in the first half and 5.4 up and 5.8 back in the second). Effector
positions are not bounded otherwise.

## Observation Space

`Box(-inf, inf, (3189,), float64)` (n = 1044 nodes):

| slice | what |
|---|---|
| `[0, 3132)` | node positions minus the worn shape (the target), n x (x, y, z) |
| `[3132, 3168)` | keypoint offsets: group centroid minus target, 12 x (x, y, z), in the order `hook_toe`, `hook_sole`, `hook_side_pos`, `hook_side_neg`, `heel`, `toe`, `instep`, `top_front`, `top_back`, `top_side_pos`, `top_side_neg`, `calf` |
| `[3168, 3171)` | the opening centre (mean of the four handle nodes) minus the tip of the foot (toe end + r forward) |
| `[3171, 3174)` | the opening's unit normal (from the handle nodes' diagonals; points out of the sock, "up" when worn) |
| `[3174, 3177)` | mean node velocity |
| `[3177, 3189)` | the four effector positions (absolute; the foot is fixed with its heel joint at the origin) |

This follows the reference hat controller (positions relative to the target, geometry of the
obstacle relative to the cloth, mean velocity, in-cloth directions) plus the effectors. The
observation carries no time: the loss switches from the hook to the wear stage at step N/2,
so a policy that should act on the stage needs the step (for example Gymnasium's
`TimeAwareObservation` wrapper).

## Rewards

The reward is minus this step's share of the loss; `info` carries the two terms:

- `hook`: sum of the 4 hook keypoint distances (the opening around the tip of the foot);
- `wear`: sum of the 8 wear keypoint distances (the sock on the foot).

With `reward = "dense"` (default) every step of the first half (t <= N/2) gets `hook / (N/2)`
and every step of the second half gets `wear / (N - N/2)`: the return is minus the time-average
of each stage's loss over its half. With `reward = "sparse"` the terms are the paper's Eq. 33
itself: `hook` at step N/2 only and `wear` at step N only (the reference evaluates its loss at
those frames only), and the return is minus Eq. 33. Distances are in scene length units.

## Starting State

The sock of the scene (`placement` puts it upright 7.5 units in front of the heel joint, its
heel 0.8 in front of the toes) turned by `yaw` degrees about the vertical axis through the
opening centre and moved by `(dx, dy, dz)`, at rest; the effectors at the handle nodes.
`reset(seed=...)` draws `dx, dy, dz` uniformly in `[start_offset_low, start_offset_high]`
(default `[-1, -1, 0]` to `[1, 1, 2]`: dz >= 0 never brings the sock closer to the toes) and
`yaw` uniformly in `[-start_yaw_deg, start_yaw_deg]` (default 45). Every start of the default
range keeps the sock at least 0.75 units out of the foot and the leg (0.76 at the closest, yaw
+-45 degrees with dz = 0, on a grid scan of the range). `reset(options={"start": (dx, dy,
dz, yaw_deg)})` sets one (out of range raises `InputError`);
`diffcloth_gym.envs.sock_v0.TEST_STARTS` holds 20 fixed starts spread over the default range
(the first 20 points of the Halton sequence in bases 2, 3, 5, 7).

## Episode End

Truncated after 400 steps (the scene's `steps`); never terminated. `info["success"]` at the end:
every wear keypoint (group centroid) within `success_distance` (default 0.5 units; the sock's
tube radius is 0.9) of its target.

## Arguments

| argument | default | meaning |
|---|---|---|
| `action_scale` | 0.05 | effector displacement per step for action 1, scene units |
| `start_offset_low` | `[-1.0, -1.0, 0.0]` | lower corner of the random start offset (dx, dy, dz) |
| `start_offset_high` | `[1.0, 1.0, 2.0]` | upper corner of the random start offset |
| `start_yaw_deg` | 45.0 | random start yaw in `[-start_yaw_deg, start_yaw_deg]` degrees |
| `keypoint_nodes` | 3 | sock nodes per keypoint group (nearest to the landmark when worn) |
| `hook_fraction` | 0.5 | the hook stage's step as a fraction of the horizon (paper: N/2) |
| `reward` | `"dense"` | `"dense"` (stage loss spread over its half) or `"sparse"` (Eq. 33 at N/2 and N) |
| `success_distance` | 0.5 | success: every wear keypoint within this distance of its target |

## Version History

- v0: initial version.
"""

from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np
import torch

from ..errors import ConfigError, InputError
from ._common import halton, merge_config, number, rotation, start_values, vector3
from .base import ClothEnv
from .task import ClothTask, Drive, Start
from .vector import ClothVectorEnv

HOOK_NAMES = ("hook_toe", "hook_sole", "hook_side_pos", "hook_side_neg")
WEAR_NAMES = ("heel", "toe", "instep", "top_front", "top_back", "top_side_pos", "top_side_neg", "calf")
#: Keypoint order of the loss and the observation: the 4 hook keypoints, then the 8 wear ones.
KEYPOINT_NAMES = HOOK_NAMES + WEAR_NAMES
#: The wear group each hook keypoint reuses (the opening's four sides).
HOOK_GROUPS = ("top_front", "top_back", "top_side_pos", "top_side_neg")

_DEFAULTS: dict[str, Any] = {
    "action_scale": 0.05,
    "start_offset_low": [-1.0, -1.0, 0.0],
    "start_offset_high": [1.0, 1.0, 2.0],
    "start_yaw_deg": 45.0,
    "keypoint_nodes": 3,
    "hook_fraction": 0.5,
    "reward": "dense",
    "success_distance": 0.5,
}


def _test_starts() -> tuple[tuple[float, float, float, float], ...]:
    lo, hi, yaw = _DEFAULTS["start_offset_low"], _DEFAULTS["start_offset_high"], _DEFAULTS["start_yaw_deg"]
    starts = []
    for i in range(1, 21):
        u = [halton(i, b) for b in (2, 3, 5, 7)]
        d = [round(lo[k] + u[k] * (hi[k] - lo[k]), 3) for k in range(3)]
        starts.append((d[0], d[1], d[2], round(-yaw + u[3] * 2 * yaw, 3)))
    return tuple(starts)


#: 20 fixed starts ``(dx, dy, dz, yaw_deg)`` spread over the default start range (Halton
#: points in bases 2, 3, 5, 7), for evaluation: ``reset(options={"start": TEST_STARTS[i]})``.
TEST_STARTS = _test_starts()


def _capsules(shape: Any):
    """The capsules ``(a, b, radius)`` of an obstacle shape (unions searched)."""
    if not isinstance(shape, Mapping):
        return
    if shape.get("kind") == "capsule":
        yield np.asarray(shape["a"], dtype=np.float64), np.asarray(shape["b"], dtype=np.float64), float(shape["radius"])
    elif shape.get("kind") == "union":
        for part in shape.get("parts", []):
            yield from _capsules(part)


def _unit(a: np.ndarray) -> np.ndarray:
    return a / np.linalg.norm(a)


class FootModel:
    """The foot and leg capsules of a scene, in the frame the landmarks use.

    ``joint``: the heel joint (where the leg and foot axes meet); ``up``: leg axis direction;
    ``forward``: foot axis direction (made orthogonal to ``up``); ``side = up x forward``;
    ``leg_top``/``toe_end``: the far ends of the two segments; radii and segment lengths."""

    def __init__(self, scene: Mapping[str, Any]):
        caps = [c for ob in scene.get("obstacles", []) or [] for c in _capsules(ob.get("shape"))]
        if len(caps) < 2:
            raise ConfigError("Sock-v0 needs a leg and a foot capsule among the scene's obstacles, "
                              f"found {len(caps)} capsule(s)")
        vertical = [abs(_unit(b - a)[1]) for a, b, _ in caps]
        leg = caps[int(np.argmax(vertical))]
        foot = caps[int(np.argmin(vertical))]
        # The joint: the pair of leg and foot endpoints closest to each other.
        pairs = [(np.linalg.norm(p - q), i, j) for i, p in enumerate(leg[:2]) for j, q in enumerate(foot[:2])]
        _, i, j = min(pairs)
        self.joint = leg[i]
        self.leg_top, self.toe_end = leg[1 - i], foot[1 - j]
        self.leg_radius, self.foot_radius = leg[2], foot[2]
        self.leg_length = float(np.linalg.norm(self.leg_top - self.joint))
        self.foot_length = float(np.linalg.norm(self.toe_end - foot[j]))
        self.up = _unit(self.leg_top - self.joint)
        fwd = self.toe_end - self.joint
        self.forward = _unit(fwd - (fwd @ self.up) * self.up)
        self.side = np.cross(self.up, self.forward)

    def wear_landmarks(self) -> np.ndarray:
        """The 8 wear landmarks (``WEAR_NAMES`` order), (8, 3): the reference's keypoints."""
        rf, rl, up, fw, sd = self.foot_radius, self.leg_radius, self.up, self.forward, self.side
        return np.array([
            self.joint - rf * up,                                         # heel
            self.toe_end + rf * fw,                                       # toe
            self.joint + 0.5 * self.foot_length * fw + rf * up,           # instep
            self.leg_top + rl * fw,                                       # top_front
            self.leg_top - rl * fw,                                       # top_back
            self.leg_top + rl * sd,                                       # top_side_pos
            self.leg_top - rl * sd,                                       # top_side_neg
            self.joint + 0.4 * self.leg_length * up - rl * fw,            # calf
        ])

    def hook_targets(self, clearance: float) -> np.ndarray:
        """The 4 hook targets (``HOOK_NAMES`` order) around the tip of the foot, (4, 3)."""
        r = self.foot_radius + clearance
        return np.array([
            self.toe_end + r * self.forward,   # hook_toe <- opening front
            self.toe_end - r * self.up,        # hook_sole <- opening back
            self.toe_end + r * self.side,      # hook_side_pos
            self.toe_end - r * self.side,      # hook_side_neg
        ])


def worn_shape(scene: Mapping[str, Any], rest_positions: np.ndarray) -> np.ndarray:
    """The sock as worn: the rest shape with the scene's ``placement`` undone (the generator
    builds the sock around the foot and leg; ``placement`` maps ``p -> R (s p) + t``)."""
    pl = scene.get("placement", {}) or {}
    s = float(pl.get("scale", 1.0))
    R = rotation(pl.get("rotate_deg", [0.0, 0.0, 0.0]))
    t = np.asarray(pl.get("translate", [0.0, 0.0, 0.0]), dtype=np.float64)
    return (np.asarray(rest_positions, dtype=np.float64) - t) @ R / s


class SockTask(ClothTask):
    """Sock-v0's task: keypoint loss, effector displacements, starts in front of the toes
    (see the module docstring)."""

    scene = "sock"
    term_names = ("hook", "wear")

    @classmethod
    def default_config(cls) -> dict[str, Any]:
        return {k: (list(v) if isinstance(v, list) else v) for k, v in _DEFAULTS.items()}

    @classmethod
    def scene_overrides(cls, config: Mapping[str, Any] | None) -> dict[str, Any]:
        """Overrides of the scene config for the task's arguments: none (the scene as shipped)."""
        merge_config(_DEFAULTS, config, "Sock-v0")
        return {}

    def __init__(self, scene: Mapping[str, Any], rest_positions: np.ndarray, handles: list[int],
                 config: Mapping[str, Any]):
        cfg = merge_config(_DEFAULTS, config, "Sock-v0")
        self.config = cfg
        self.action_scale = number(cfg, "action_scale", 0.0, open_lo=True)
        self.start_low = vector3(cfg, "start_offset_low")
        self.start_high = vector3(cfg, "start_offset_high")
        if np.any(self.start_low > self.start_high):
            raise ConfigError(f"start_offset_low {cfg['start_offset_low']} exceeds start_offset_high "
                              f"{cfg['start_offset_high']}")
        self.start_yaw = number(cfg, "start_yaw_deg", 0.0, 180.0)
        k = cfg["keypoint_nodes"]
        if isinstance(k, bool) or not isinstance(k, int) or k < 1:
            raise ConfigError(f"keypoint_nodes must be a positive integer, got {k!r}")
        hook_fraction = number(cfg, "hook_fraction", 0.0, 1.0, open_lo=True)
        if cfg["reward"] not in ("dense", "sparse"):
            raise ConfigError(f"reward must be 'dense' or 'sparse', got {cfg['reward']!r}")
        self.dense = cfg["reward"] == "dense"
        self.success_distance = number(cfg, "success_distance", 0.0, open_lo=True)

        rest = np.asarray(rest_positions, dtype=np.float64)
        n = rest.shape[0]
        self.handles = [int(i) for i in handles]
        if len(self.handles) != 4:
            raise ConfigError(f"Sock-v0 drives 4 rim handles, the scene attaches {len(self.handles)} node(s)")
        if k > n:
            raise ConfigError(f"keypoint_nodes must be at most the number of nodes ({n}), got {k}")
        self.horizon = int(scene.get("steps", 400))
        self.hook_step = max(1, min(self.horizon, round(hook_fraction * self.horizon)))
        self.action_dim = 3 * len(self.handles)
        self.action_bound = 1.0
        self.obs_dim = 3 * n + 3 * len(KEYPOINT_NAMES) + 3 + 3 + 3 + self.action_dim

        self.rest = rest
        self.foot = FootModel(scene)
        worn = worn_shape(scene, rest)
        # Groups: the k nodes nearest to each wear landmark in the worn shape.
        landmarks = self.foot.wear_landmarks()
        wear_groups = np.argsort(np.linalg.norm(worn[None] - landmarks[:, None], axis=-1), axis=1)[:, :k]
        wear_targets = worn[wear_groups].mean(axis=1)
        # The sock's clearance over the leg: the worn opening's radius minus the leg's radius.
        rel = worn[self.handles] - self.foot.joint
        radial = rel - np.outer(rel @ self.foot.up, self.foot.up)
        self.clearance = max(0.0, float(np.linalg.norm(radial, axis=1).mean()) - self.foot.leg_radius)
        hook_groups = wear_groups[[WEAR_NAMES.index(g) for g in HOOK_GROUPS]]
        self.groups = np.concatenate([hook_groups, wear_groups])          # (12, k)
        targets = np.concatenate([self.foot.hook_targets(self.clearance), wear_targets])
        self.landmarks = landmarks
        self.toe_tip = self.foot.toe_end + self.foot.foot_radius * self.foot.forward
        # Sign making the handle-diagonal normal point out of the opening ("up" when worn).
        h = worn[self.handles]
        self._normal_sign = 1.0 if np.cross(h[1] - h[3], h[0] - h[2]) @ self.foot.up >= 0 else -1.0
        # The opening centre's yaw axis for starts (vertical through the handles' centroid).
        self._start_centre = rest[self.handles].mean(axis=0)

        f64 = torch.float64
        self._worn = torch.tensor(worn, dtype=f64)
        self._groups = torch.tensor(self.groups, dtype=torch.long)
        self._targets = torch.tensor(targets, dtype=f64)
        self._toe_tip = torch.tensor(self.toe_tip, dtype=f64)
        self._handles = torch.tensor(self.handles, dtype=torch.long)
        self.worn = worn
        self.targets = targets

    # -- starts ----------------------------------------------------------------------------
    def sample_start(self, rng: np.random.Generator) -> Start:
        d = rng.uniform(self.start_low, self.start_high)
        yaw = rng.uniform(-self.start_yaw, self.start_yaw)
        return self.start((float(d[0]), float(d[1]), float(d[2]), float(yaw)))

    def start(self, spec: Any) -> Start:
        vals = start_values(spec, ("dx", "dy", "dz", "yaw_deg"))
        d, yaw = np.array(vals[:3]), vals[3]
        eps = 1e-9
        if np.any(d < self.start_low - eps) or np.any(d > self.start_high + eps) or abs(yaw) > self.start_yaw + eps:
            raise InputError(
                f"start {tuple(vals)} is out of range: (dx, dy, dz) in [{self.start_low.tolist()}, "
                f"{self.start_high.tolist()}], yaw_deg in [-{self.start_yaw}, {self.start_yaw}]")
        R = rotation([0.0, yaw, 0.0])
        x = (self.rest - self._start_centre) @ R.T + self._start_centre + d
        return Start(x=x, v=np.zeros_like(x), control=x[self.handles].copy())

    # -- dynamics, observation, loss ---------------------------------------------------------
    def drive(self, control: torch.Tensor, action: torch.Tensor) -> tuple[torch.Tensor, Drive]:
        new = control + self.action_scale * action.reshape(control.shape)
        return new, Drive(targets=new, forces=None)

    def keypoint_offsets(self, x: torch.Tensor) -> torch.Tensor:
        """Group centroid minus target per keypoint (``KEYPOINT_NAMES`` order), (B, 12, 3)."""
        centroids = x[:, self._groups.to(x.device)].mean(dim=2)
        return centroids - self._targets.to(x)

    def keypoint_distances(self, x: torch.Tensor) -> torch.Tensor:
        """Distance of each keypoint group's centroid to its target, (B, 12)."""
        return torch.linalg.vector_norm(self.keypoint_offsets(x), dim=-1)

    def observe(self, x: torch.Tensor, v: torch.Tensor, control: torch.Tensor) -> torch.Tensor:
        B = x.shape[0]
        h = x[:, self._handles.to(x.device)]
        normal = self._normal_sign * torch.linalg.cross(h[:, 1] - h[:, 3], h[:, 0] - h[:, 2], dim=-1)
        normal = torch.nn.functional.normalize(normal, dim=-1)
        return torch.cat([
            (x - self._worn.to(x)).reshape(B, -1),
            self.keypoint_offsets(x).reshape(B, -1),
            h.mean(dim=1) - self._toe_tip.to(x),
            normal,
            v.mean(dim=1),
            control.reshape(B, -1),
        ], dim=1)

    def _weights(self, step: int) -> tuple[float, float]:
        N, M = self.horizon, self.hook_step
        if self.dense:
            hook = 1.0 / M if 1 <= step <= M else 0.0
            wear = 1.0 / (N - M) if M < step <= N else 0.0
            return hook, wear
        return (1.0 if step == M else 0.0), (1.0 if step == N else 0.0)

    def loss_terms(self, x: torch.Tensor, v: torch.Tensor, control: torch.Tensor,
                   step: int) -> dict[str, torch.Tensor]:
        d = self.keypoint_distances(x)
        w_hook, w_wear = self._weights(int(step))
        n_hook = len(HOOK_NAMES)
        # paper Eqn. 33: sum of the L2 distances of the keypoint pairs of each stage
        return {"hook": w_hook * d[:, :n_hook].sum(dim=1), "wear": w_wear * d[:, n_hook:].sum(dim=1)}

    def success(self, x: torch.Tensor, v: torch.Tensor, control: torch.Tensor) -> torch.Tensor:
        d = self.keypoint_distances(x)[:, len(HOOK_NAMES):]
        return (d < self.success_distance).all(dim=1)


class SockEnv(ClothEnv):
    task_class = SockTask


class SockVectorEnv(ClothVectorEnv):
    task_class = SockTask


# The env's documentation is this module's (Gymnasium's sections, above).
SockEnv.__doc__ = SockVectorEnv.__doc__ = __doc__
