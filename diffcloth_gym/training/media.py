"""Pictures of evaluation rollouts: frames of node positions rendered by the package's software
renderer (``diffcloth_gym.rendering``) on a simulator of the env's scene, or, where that
renderer is not available, by a matplotlib surface plot; tiled over several starts and written
as a GIF (Pillow, which matplotlib already depends on)."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

import numpy as np


class FrameRenderer:
    """Renders (n, 3) node positions of one env's scene as HxWx3 uint8 frames."""

    def __init__(self, engine: Any, size: int = 240):
        from diffcloth_gym.simulator import Simulator

        self.sim = Simulator.from_config(engine.scene)
        self.size = size
        self.triangles = np.asarray(self.sim.triangles)
        try:
            from diffcloth_gym import rendering

            self._rgb = rendering.render_rgb
        except (ImportError, AttributeError):
            self._rgb = None
        self._camera = None

    def __call__(self, positions: np.ndarray) -> np.ndarray:
        self.sim.reset(x=positions)
        if self._rgb is not None:
            return np.asarray(self._rgb(self.sim, self.size, self.size, self._camera))
        return self._matplotlib(positions)

    def set_view(self, points: np.ndarray, state: np.ndarray) -> None:
        """Fixes one camera for every frame of a GIF: the renderer's default view of ``state``
        (n, 3), or (matplotlib) the box around all ``points`` (m, 3)."""
        self._bounds = (points.min(axis=0), points.max(axis=0))
        if self._rgb is None:
            return
        from diffcloth_gym import rendering

        self.sim.reset(x=state)
        self._camera = rendering.default_camera(self.sim, self.size, self.size)

    def _matplotlib(self, x: np.ndarray) -> np.ndarray:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        dpi = 80
        fig = plt.figure(figsize=(self.size / dpi, self.size / dpi), dpi=dpi)
        ax = fig.add_subplot(projection="3d")
        # y is up in the scenes; matplotlib's vertical axis is z.
        ax.plot_trisurf(x[:, 0], x[:, 2], x[:, 1], triangles=self.triangles, color="tab:blue", linewidth=0.1,
                        edgecolor="k", alpha=0.9)
        lo, hi = getattr(self, "_bounds", (x.min(axis=0), x.max(axis=0)))
        c, r = (lo + hi) / 2, max(float((hi - lo).max()) / 2, 1e-3)
        ax.set_xlim(c[0] - r, c[0] + r)
        ax.set_ylim(c[2] - r, c[2] + r)
        ax.set_zlim(c[1] - r, c[1] + r)
        ax.set_axis_off()
        fig.canvas.draw()
        frame = np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()
        plt.close(fig)
        return frame


def tile(frames: Sequence[np.ndarray], cols: int) -> np.ndarray:
    """Frames of one size side by side, ``cols`` per row (blank cells filled white)."""
    h, w, _ = frames[0].shape
    rows = -(-len(frames) // cols)
    out = np.full((rows * h, cols * w, 3), 255, dtype=np.uint8)
    for k, f in enumerate(frames):
        r, c = divmod(k, cols)
        out[r * h:(r + 1) * h, c * w:(c + 1) * w] = f
    return out


def rollout_gif(engine: Any, frames: Sequence[np.ndarray], path: str | Path, size: int = 240, cols: int = 2,
                fps: float = 10.0) -> Path:
    """A GIF of an evaluation's ``frames`` (each (S, n, 3): every start's positions at one
    time), the starts tiled ``cols`` per row, one camera over the whole rollout."""
    from PIL import Image

    render = FrameRenderer(engine, size)
    allpos = np.concatenate([f.reshape(-1, 3) for f in frames])
    render.set_view(allpos, frames[0][0])
    images = [Image.fromarray(tile([render(x) for x in f], cols)) for f in frames]
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    images[0].save(path, save_all=True, append_images=images[1:], duration=int(1000 / fps), loop=0)
    return path
