"""The main job (for now): simulate a scene (default: a cloth dropped on a sphere, with dry
friction and self-collision) and write a picture of its motion.

Run with ``scripts/demo`` (or ``python -m diffcloth_gym.demo``). The hat-controller comparison
replaces this once the environments and gradients exist.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np


def main(argv: list[str] | None = None) -> Path:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--scene", default="sphere", help="shipped scene name (diffcloth_gym/configs/) or a TOML path")
    parser.add_argument("--steps", type=int, default=None, help="steps (default: the scene's)")
    parser.add_argument("--out", default="out/demo.png", help="picture to write")
    args = parser.parse_args(argv)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from diffcloth_gym import Simulator

    sim = Simulator.from_config(args.scene)
    steps = args.steps or sim.config.get("steps", 100)
    frames = [sim.positions]
    start = time.perf_counter()
    for _ in range(steps):
        sim.step()
        frames.append(sim.positions)
    elapsed = time.perf_counter() - start
    prof = sim.profile()
    print(
        f"{args.scene}: {sim.num_nodes} nodes, {steps} steps in {elapsed:.2f} s "
        f"({1e3 * elapsed / steps:.2f} ms/step, {prof['iterations'] / steps:.1f} PD iterations/step)"
    )

    picks = np.linspace(0, steps, 5).astype(int)
    fig = plt.figure(figsize=(4 * len(picks), 4.2))
    tris = sim.triangles
    lo = np.min([f.min(axis=0) for f in frames], axis=0)
    hi = np.max([f.max(axis=0) for f in frames], axis=0)
    for k, i in enumerate(picks):
        ax = fig.add_subplot(1, len(picks), k + 1, projection="3d")
        x = frames[i]
        # Matplotlib's z is up; our y is up.
        ax.plot_trisurf(x[:, 0], x[:, 2], x[:, 1], triangles=tris, color="tab:blue", alpha=0.85, linewidth=0.2, edgecolor="k")
        for obstacle in sim.config.get("obstacles", []):
            shape = obstacle["shape"]
            if shape["kind"] == "sphere":
                u, w = np.meshgrid(np.linspace(0, 2 * np.pi, 24), np.linspace(0, np.pi, 12))
                c, r = shape["center"], shape["radius"]
                ax.plot_surface(c[0] + r * np.cos(u) * np.sin(w), c[2] + r * np.sin(u) * np.sin(w),
                                c[1] + r * np.cos(w), color="tab:orange", alpha=0.35, linewidth=0)
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[2], hi[2])
        ax.set_zlim(lo[1], hi[1])
        ax.set_box_aspect((hi[0] - lo[0], max(hi[2] - lo[2], 1e-3), hi[1] - lo[1]))
        ax.set_title(f"t = {i * sim.params()['h']:.2f} s")
        ax.set_axis_off()
    fig.suptitle(f"diffcloth-gym: {args.scene} ({sim.num_nodes} nodes)")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=80, bbox_inches="tight")
    print(f"wrote {out}")
    return out


if __name__ == "__main__":
    main()
