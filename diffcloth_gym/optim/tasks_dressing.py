"""Robot-assisted dressing (paper Sec. 6.2, App. B.2): end-effector trajectories as cubic
Hermite splines that put a hat on a head (18 numbers) or a sock on a foot (36 numbers). The
scenes, starts, targets and keypoints are the environments' (``diffcloth_gym.envs.hat_v0``,
``sock_v0``): one definition of each task's geometry. Needs torch (the environments' loss
code is imported for its geometry only)."""

from __future__ import annotations

import numpy as np

from diffcloth_gym.errors import InputError
from diffcloth_gym.optim.losses import GroupKeypoints, ShapeMatch, Sum
from diffcloth_gym.optim.spline import HermiteSpline
from diffcloth_gym.optim.tasks import Task
from diffcloth_gym.scenes import load_scene
from diffcloth_gym.simulator import Simulator

#: Where the reference starts the hat, relative to the head's centre: its head at (0, -1.606 +
#: 2.1, -8) and its hat's node centroid at (0.012, -0.251, -0.355) (see hat_v0's Starting
#: State): 7.68 units away, 7.645 of them horizontal, the hat 0.745 below the head's centre.
HAT_START_OFFSET = np.array([0.012, -0.745, 7.645])


def _steps(steps, default: int) -> int:
    steps = default if steps is None else steps
    if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 1:
        raise InputError(f"steps must be a positive integer, got {steps!r}")
    return int(steps)


def hat(steps: int | None = None, reach: float = 10.0, tangent: float = 15.0) -> Task:
    """Hat (paper Fig. 9, Eqn. 32): the ``hat`` scene (procedural hat, 618 nodes, h = 1/100 s,
    400 steps) starting where the reference starts it (:data:`HAT_START_OFFSET` from the head's
    centre, upright, at rest); two effectors on the brim handles follow Hermite splines
    (endpoint displacement in [-reach, reach], tangents in [-tangent, tangent] per component:
    18 numbers); loss ``|x_N - target|`` with Hat-v0's target shape (the hat resting on the
    head). The zero vector keeps the effectors still."""
    from diffcloth_gym.envs.hat_v0 import HatTask

    cfg = load_scene("hat")
    steps = _steps(steps, cfg["steps"])
    sim = Simulator.from_config(cfg)
    rest = sim.rest_positions
    env_task = HatTask(cfg, rest, sim.handles, {})
    x0 = rest + (env_task.head_center + HAT_START_OFFSET - rest.mean(axis=0))
    param = HermiteSpline(x0[sim.attachment_nodes], reach=reach, tangent=tangent)
    loss = ShapeMatch(env_task.target_np)
    return Task("hat", sim, param, loss, steps, x0=x0,
                notes="procedural 618-node hat (hat579.obj has 579); the target is Hat-v0's settled hat on the head "
                      "(the paper's: its rest shape translated onto the head)")


def sock(steps: int | None = None, reach: float = 10.0, tangent: float = 15.0) -> Task:
    """Sock (paper Fig. 10, Eqn. 33): the ``sock`` scene (procedural sock, 1044 nodes, h = 1/160
    s, 400 steps) at its rest placement in front of the toes; four effectors on the rim handles
    follow Hermite splines (36 numbers); loss: Sock-v0's keypoints, the four opening groups
    against points around the tip of the foot at step N/2 and the eight wear groups against
    their worn positions at step N (group centroids, see ``sock_v0``)."""
    from diffcloth_gym.envs.sock_v0 import SockTask

    cfg = load_scene("sock")
    steps = _steps(steps, cfg["steps"])
    sim = Simulator.from_config(cfg)
    env_task = SockTask(cfg, sim.rest_positions, sim.handles, {})
    hook_step = max(0, steps // 2 - 1)
    groups, targets = env_task.groups, env_task.targets
    loss = Sum([GroupKeypoints(groups[:4], targets[:4], step=hook_step), GroupKeypoints(groups[4:], targets[4:])])
    param = HermiteSpline(sim.rest_positions[sim.attachment_nodes], reach=reach, tangent=tangent)
    return Task("sock", sim, param, loss, steps,
                notes="procedural 1044-node sock (sock1055.obj has 1055); keypoints are Sock-v0's group centroids")
