"""The garment cases: the shipped Hat and Sock (contact with the body, friction,
self-collision) driven by smooth random handle paths from seeded random placements."""

from __future__ import annotations

import copy
import math
from pathlib import Path
from typing import Callable

import numpy as np

from benchmarks.stability.builders import smooth_walk
from benchmarks.stability.harness import backward, finish, pick, run
from benchmarks.stability.metrics import Monitor
from diffcloth_gym import Simulator
from diffcloth_gym.scenes import load_scene


def garment_setups(scene: str, count: int) -> list[tuple[dict, Callable[[int], np.ndarray], np.ndarray]]:
    """The first ``count`` seeded random starts of a garment case (``"hat"`` or ``"sock"``):
    ``(config, targets, goal)`` with ``targets(k)`` the handles' targets at step k. Placements
    are redrawn until the garment starts clear of the body by more than the contact distance."""
    base = load_scene(scene)
    rng = np.random.default_rng({"hat": 11, "sock": 12}[scene])
    if scene == "hat":  # lower the hat onto the head, aim the loss at the top of the head
        drift, goal = np.array([0.0, -0.4, 0.0]), np.array([0.0, 2.1, 0.0])
    else:  # push the sock towards the foot, aim at the middle of the foot
        drift, goal = np.array([0.0, 0.0, -0.6]), np.array([0.0, 0.0, 2.5])
    setups = []
    for _ in range(count):
        cfg = copy.deepcopy(base)
        while True:
            if scene == "hat":  # above the head (sphere r 2.1 at the origin), tilted, turned
                cfg["placement"] = {"translate": [rng.uniform(-0.4, 0.4), rng.uniform(1.9, 2.4), rng.uniform(-0.4, 0.4)],
                                    "rotate_deg": [rng.uniform(-10, 10), rng.uniform(0, 360), rng.uniform(-10, 10)]}
            else:  # in front of the toes (foot capsule to z = 5.7), offset and turned
                cfg["placement"] = {"translate": [rng.uniform(-0.3, 0.3), rng.uniform(-0.2, 0.2), rng.uniform(6.7, 7.1)],
                                    "rotate_deg": [rng.uniform(-5, 5), rng.uniform(-15, 15), rng.uniform(-5, 5)]}
            sim = Simulator.from_config(cfg)
            # thickness + margin = 0.02: nothing may start in contact.
            if sim.obstacle_distance(0).min() > 0.03:
                break
        h = sim.params()["h"]
        start = sim.attachment_targets.copy()
        common = smooth_walk(rng, GARMENT_COMMON_SPEED)
        own = [smooth_walk(rng, GARMENT_OWN_SPEED) for _ in start]

        def targets(k: int, start=start, common=common, own=own, h=h) -> np.ndarray:
            t = (k + 1) * h
            return start + drift * t + common(t) + np.array([w(t) for w in own])

        setups.append((cfg, targets, goal))
    return setups


#: Garment handles: per-axis speed bound of the walk shared by all handles and of each handle's own.
GARMENT_COMMON_SPEED = 0.3
GARMENT_OWN_SPEED = 0.15


def _garment_rollouts(size: str, scene: str) -> dict:
    """Shared body of the garment cases: :func:`garment_setups` (CI runs the first 2 of the full
    run's 20), forward with recording and a loss on every step (mean squared distance to a body
    point), Krylov backward."""
    placements, steps = pick(size, (2, 80 if scene == "hat" else 100), (20, 400))
    mon = Monitor(energy=False)
    clearances = []
    for cfg, targets, goal in garment_setups(scene, placements):
        sim = Simulator.from_config(cfg)
        clearances.append(float(sim.obstacle_distance(0).min()))
        sim.set_recording(True)
        dl_dx = run(sim, mon, steps, targets=targets,
                    loss_grad=lambda s: 2 * (s.positions - goal) / (s.num_nodes * steps))
        backward(sim, mon, dl_dx)
    drift = 0.4 if scene == "hat" else 0.6
    max_speed = math.sqrt(3) * (GARMENT_COMMON_SPEED + GARMENT_OWN_SPEED) + drift
    return finish(mon, {
        "touches_body": (mon.obstacle_contacts > 0, f"{mon.obstacle_contacts} active obstacle contacts"),
    }, None, placements=placements, handle_speed_bound_m_s=max_speed, min_start_clearance_m=min(clearances))


def case_hat_random(size: str, workdir: Path) -> dict:
    """``hat.toml`` (618 nodes, head sphere on a neck, friction, self-collision): the two brim
    handles follow smooth random walks (<= ~1.2 m/s) while lowering the hat onto the head, from
    20 random placements above the head (offset +-0.4 m, tilt +-10 deg, any turn); forward and
    backward with a loss on every step. Full: 20 x 400 steps; CI: 2 x 80."""
    return _garment_rollouts(size, "hat")


def case_sock_random(size: str, workdir: Path) -> dict:
    """``sock.toml`` (1044 nodes, foot and leg capsules, friction, self-collision): the four
    opening handles follow smooth random walks (<= ~1.4 m/s) while pushing the sock onto the
    toes, from 20 random placements in front of the foot (offset +-0.3 m, turn +-15 deg);
    forward and backward with a loss on every step. Full: 20 x 400 steps; CI: 2 x 100."""
    return _garment_rollouts(size, "sock")
