"""What every part of the accuracy study shares: the :class:`Scene`, single-threaded
simulators, rollouts timed inside Rust with a guard against a shared machine, and the
Markdown and plot helpers of the report."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence, TypeVar

import numpy as np

from diffcloth_gym import Simulator
from diffcloth_gym.scenes import contact_free, load_scene

T = TypeVar("T")

#: Effector velocity (m/s) of the garments in the forward and time-step parts: the same motion
#: as the gradient part at the Hat's h = 0.01 s, so that the hat swings instead of settling.
GARMENT_DRIVE = (0.0, -0.3, 0.2)


@dataclass(frozen=True)
class Scene:
    """A scene of the study: a config plus how long and how it is driven."""

    label: str
    config: dict
    steps: int
    #: Effector (attachment target) velocity in m/s, or None to keep the targets fixed.
    drive: tuple[float, float, float] | None = None
    #: Standard deviation of the seeded random initial velocities (0: start at rest).
    v_sigma: float = 0.0
    #: ``x0`` / ``v0``: an initial state other than the scene's own (``v0`` overrides v_sigma);
    #: ``targets``: per-step attachment targets (steps, k, 3), instead of ``drive``.
    extra: dict = field(default_factory=dict)


def grid_scene(name: str, res: int, steps: int, v_sigma: float = 0.0) -> Scene:
    """Wind or Slope at ``res x res`` nodes."""
    return Scene(f"{name}{res}x{res}", load_scene(name, rows=res, cols=res), steps, None, v_sigma)


def garment_scene(name: str, steps: int, contact: bool = False, drive: Any = GARMENT_DRIVE) -> Scene:
    """Hat or Sock, contact-free (as in the gradient consistency test) unless ``contact``."""
    cfg = load_scene(name)
    label = name if contact else f"{name}_nocontact"
    return Scene(label, cfg if contact else contact_free(cfg), steps, drive)


def sphere_scene(res: int, steps: int) -> Scene:
    """The sphere drop at ``res x res`` nodes, placed just above the sphere at the shipped
    drop's impact speed (``gradient_cost``'s case): contact from the first steps."""
    from benchmarks.gradient_cost import sphere_case

    case = sphere_case(res, steps)
    return Scene(case.name, case.cfg, steps, extra={"x0": case.x0, "v0": case.v0})


def hat_on_head_scene(steps: int, start: int = 240) -> Scene:
    """Hat-v0's scene (head, friction, self-collision) with its effectors carrying the hat from
    start (0, 0) onto the head over 250 steps and then holding (``gradient_cost``'s case), timed
    from step ``start``, as the hat lands, for ``steps`` steps: the study's contact regime (the
    Hat driven at GARMENT_DRIVE no longer reaches the head since the edge-bending default). The
    state at ``start`` comes from one Anderson rollout at 1e-12."""
    from benchmarks.gradient_cost import hat_case

    case = hat_case(start + steps)
    sim = make_sim(case.cfg, acceleration="anderson", polish="none", tolerance=1e-12, max_iterations=20000)
    sim.reset(x=case.x0, v=case.v0)
    for k in range(start):
        sim.step(attachment_targets=case.targets[k])
    return Scene("hat_on_head", case.cfg, steps,
                 extra={"x0": sim.positions.copy(), "v0": sim.velocities.copy(), "targets": case.targets[start:]})


def gradient_tolerance() -> float:
    """The tolerance of the simulator's ``gradient`` solver preset (what recorded steps need)."""
    return gradient_preset()["tolerance"]


def gradient_preset() -> dict:
    """The simulator's ``gradient`` solver preset (tolerance and iteration cap)."""
    sim = Simulator.from_config("napkin")
    sim.set_solver(preset="gradient")
    return sim.solver()


def make_sim(cfg: dict, **solver: Any) -> Simulator:
    """A single-threaded simulator (the study compares algorithms, not thread counts)."""
    sim = Simulator.from_config(cfg)
    sim.set_solver(parallel=False, **solver)
    return sim


def initial_velocities(sim: Simulator, sigma: float, seed: int = 0) -> np.ndarray | None:
    """Seeded random initial velocities (None for rest): identical for every run of a scene."""
    if sigma == 0.0:
        return None
    return np.random.default_rng(seed).normal(0.0, sigma, (sim.num_nodes, 3))


#: Timing guard counters (reported in the meta block): reruns because another process took
#: the core, and measurements still disturbed after the last rerun.
TIMING = {"reruns": 0, "disturbed": 0}
#: A run counts as disturbed when its time inside Rust exceeds the thread's CPU time by this
#: factor (plus 2 ms): the single-threaded simulator then waited for a core.
DISTURBED_RATIO = 1.25
RERUNS = 2


def undisturbed(run: Callable[[], T], rust_seconds: Callable[[T], float]) -> T:
    """Runs ``run`` (deterministic) and reruns it up to RERUNS times while it was disturbed;
    returns the run with the least time inside Rust.

    The machine is shared: when other jobs occupy both cores, the Rust wall-clock profile of a
    single-threaded run inflates (seen: 10x on one Hat setting) while its thread CPU time does
    not, so the two are compared to detect it.
    """
    best, best_s = None, math.inf
    for attempt in range(1 + RERUNS):
        cpu = time.thread_time()
        out = run()
        rust_s, cpu_s = rust_seconds(out), time.thread_time() - cpu
        if rust_s < best_s:
            best, best_s = out, rust_s
        if rust_s <= DISTURBED_RATIO * cpu_s + 2e-3:
            return best
        if attempt < RERUNS:
            TIMING["reruns"] += 1
    TIMING["disturbed"] += 1
    return best


def rollout(sim: Simulator, scene: Scene, steps: int, h: float | None = None) -> tuple[np.ndarray, dict, int]:
    """Runs ``steps`` steps from the scene's initial state with the current solver settings.

    Returns the trajectory (steps + 1, n, 3), the Rust profile of just these steps, and the
    number of steps that stopped unconverged. Effector targets move with ``scene.drive``,
    evaluated at the end of each step (implicit Euler), so that runs at different h see the
    same motion in time. Rerun if another process disturbed the timing (see undisturbed).
    """
    return undisturbed(lambda: _rollout_once(sim, scene, steps, h), lambda out: out[1]["total_s"])


def _rollout_once(sim: Simulator, scene: Scene, steps: int, h: float | None) -> tuple[np.ndarray, dict, int]:
    h = sim.params()["h"] if h is None else h
    v0 = scene.extra.get("v0")
    sim.reset(x=scene.extra.get("x0"), v=initial_velocities(sim, scene.v_sigma) if v0 is None else v0)
    t0 = sim.attachment_targets
    traj = np.empty((steps + 1, sim.num_nodes, 3))
    traj[0] = sim.positions
    unconverged = 0
    sim.reset_profile()
    for k in range(steps):
        if "targets" in scene.extra:
            targets = scene.extra["targets"][k]
        else:
            targets = None if scene.drive is None else t0 + np.asarray(scene.drive) * (k + 1) * h
        unconverged += not sim.step(attachment_targets=targets)["converged"]
        traj[k + 1] = sim.positions
    return traj, sim.profile(), unconverged


def _fmt(v: Any) -> str:
    """Table cells: scientific for small/large floats, blank for None."""
    if v is None:
        return ""
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float) and not math.isnan(v):
        if v == 0:
            return "0"
        if abs(v) >= 1e4 or abs(v) < 1e-2:
            return f"{v:.2e}"
        return f"{v:.3g}"
    return str(v)


def table(rows: list[dict], columns: list[str], headers: list[str] | None = None) -> str:
    """A Markdown table of ``rows`` restricted to ``columns``."""
    lines = ["| " + " | ".join(headers or columns) + " |", "|" + "---|" * len(columns)]
    lines += ["| " + " | ".join(_fmt(r.get(c)) for c in columns) + " |" for r in rows]
    return "\n".join(lines)


def pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def no_minor_labels(ax: Any) -> None:
    """Minor tick labels of short log decades overlap; the grid shows the minor ticks."""
    from matplotlib.ticker import NullFormatter

    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.yaxis.set_minor_formatter(NullFormatter())


def save_plot(fig: Any, axes: Sequence[Any], out_dir: Path, name: str) -> list[str]:
    """Grid, major-only labels and a legend on each axis; writes ``name`` and closes the figure."""
    for ax in axes:
        ax.grid(True, which="both", alpha=0.3)
        no_minor_labels(ax)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out_dir / name, dpi=110)
    pyplot().close(fig)
    return [name]
