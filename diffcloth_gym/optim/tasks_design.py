"""Inverse design (paper Sec. 6.3, Fig. 1, App. B.3): the twirling dress. A skirt held at its
waist is spun about the vertical axis; its density and bending stiffness are chosen so that at
the end the hem has risen to the height of a target apex angle."""

from __future__ import annotations

import math

import numpy as np

from diffcloth_gym.errors import InputError
from diffcloth_gym.optim.losses import HeightMatch
from diffcloth_gym.optim.parameterization import Fixed, Stack
from diffcloth_gym.optim.physical import PhysicalParams
from diffcloth_gym.optim.tasks import Task, task_scene
from diffcloth_gym.optim.tasks_meshes import MESHES, mesh
from diffcloth_gym.simulator import Simulator


def twirl(points: np.ndarray, steps: int, h: float, omega: float, ramp: float) -> np.ndarray:
    """(steps, k, 3) targets turning ``points`` about the y axis: angular speed rising
    linearly from 0 to ``omega`` (rad/s) over ``ramp`` seconds, then constant; step n's target
    is the pose at the end of the step, t = (n + 1) h."""
    t = (np.arange(steps) + 1) * h
    theta = np.where(t < ramp, omega * t * t / (2 * ramp), omega * (t - ramp / 2))
    c, s = np.cos(theta), np.sin(theta)
    p = np.asarray(points, dtype=np.float64)
    out = np.empty((steps, len(p), 3))
    out[..., 0] = c[:, None] * p[:, 0] + s[:, None] * p[:, 2]
    out[..., 1] = p[:, 1]
    out[..., 2] = -s[:, None] * p[:, 0] + c[:, None] * p[:, 2]
    return out


def apex_angle(x: np.ndarray, waist: np.ndarray, hem: np.ndarray) -> float:
    """The apex angle (degrees) of the cone through the waist and hem rings of positions ``x``
    (n, 3), about the y axis: ``2 atan((r_hem - r_waist) / (y_waist - y_hem))`` with ring-mean
    radii and heights."""
    r = np.linalg.norm(x[:, [0, 2]], axis=1)
    return 2.0 * math.degrees(math.atan2(r[hem].mean() - r[waist].mean(), x[waist, 1].mean() - x[hem, 1].mean()))


def dress(target_deg: float = 100.0, steps: int | None = None, omega: float = 1.5, ramp: float = 0.3,
          bounds: dict | None = None) -> Task:
    """The ``dress`` scene (procedural skirt, 192 nodes: 24 waist nodes attached; h = 1/120 s,
    125 steps, density 0.3, k_stretch 3000, k_bend 0.3 as the reference) twirled at ``omega``
    rad/s (reached after ``ramp`` s); optimizes ``density`` in [0.05, 1] and ``k_bend`` in
    [0.01, 1] so that the hem ends at the height ``-L cos(target / 2)`` below the waist (``L``
    = 3, the skirt's length along the cone), the height where a cone of apex angle ``target``
    (100 degrees, as the paper) puts it. Loss: the paper's Eqn. 34 on the final step.
    ``Task.measure`` reports the final apex angle."""
    if not (isinstance(target_deg, (int, float)) and 0 < target_deg < 180):
        raise InputError(f"target_deg must be an angle in (0, 180) degrees, got {target_deg!r}")
    cfg = task_scene("dress")
    steps = cfg["steps"] if steps is None else steps
    if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 1:
        raise InputError(f"steps must be a positive integer, got {steps!r}")
    sim = Simulator.from_config(cfg)
    _, _, sets = mesh("dress_skirt.obj")
    length = MESHES["dress_skirt.obj"][1]["length"]
    waist, hem = np.asarray(sets["waist"]), np.asarray(sets["hem"])
    spec = bounds or {"density": (0.05, 1.0), "k_bend": (0.01, 1.0)}
    physical = PhysicalParams(sim, spec)
    targets = twirl(sim.rest_positions[sim.attachment_nodes], int(steps), cfg["h"], omega, ramp)
    param = Stack([physical, Fixed(targets=targets)])
    waist_y = float(sim.rest_positions[waist, 1].mean())
    height = waist_y - length * math.cos(math.radians(target_deg) / 2)
    loss = HeightMatch(hem, height)

    def measure(xs):
        return {"apex_angle_deg": apex_angle(xs[-1], waist, hem), "target_deg": float(target_deg)}

    return Task("dress", sim, param, loss, int(steps), measure=measure,
                notes=f"procedural 192-node skirt (dress3634.obj has 3634 vertices); twirl {omega} rad/s after a "
                      f"{ramp} s ramp (the reference's twirl speed is not in its scene table)",
                extra={"target_height": height, "waist": waist.tolist(), "hem": hem.tolist()})
