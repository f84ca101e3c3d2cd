"""Frames of a simulator for videos and viewers: RGB arrays from the Rust software renderer
(no OpenGL, works headless), and a matplotlib window for ``render_mode="human"``.

``camera`` (optional) is a dict with any of ``eye``, ``target``, ``up`` (3 numbers each, scene
units) and ``fov`` (vertical field of view, degrees); entries left out come from the default
framing, which fits the scene's rest shape, obstacles and floor and stays fixed over a run
(see :func:`default_camera`). The cloth's two sides have different colours (red where the
triangles' normals point, ochre on the other side), obstacles are grey, attachment targets
(the end effectors) green discs.
"""

from __future__ import annotations

import os
import sys
from typing import Any, Mapping

import numpy as np

from diffcloth_gym import _core
from diffcloth_gym.errors import InputError

__all__ = ["HumanViewer", "default_camera", "render_member", "render_rgb"]


def _renderer(sim, width: int, height: int) -> _core.Renderer:
    """The simulator's renderer of this size, kept on the simulator so that its buffers are
    reused frame after frame."""
    cached = getattr(sim, "_renderer", None)
    if cached is not None and (cached.width, cached.height) == (width, height):
        return cached
    renderer = _core.Renderer(width, height)
    sim._renderer = renderer
    return renderer


def _camera(camera: Mapping[str, Any] | None) -> dict | None:
    if camera is None:
        return None
    if not isinstance(camera, Mapping):
        raise InputError(f"camera must be a dict with eye, target, up, fov, got {type(camera).__name__}")
    return dict(camera)


def render_rgb(sim, width: int = 480, height: int = 480, camera: Mapping[str, Any] | None = None) -> np.ndarray:
    """The simulator's current state as a (height, width, 3) uint8 RGB frame (a new array)."""
    return _renderer(sim, width, height).render(sim._core, _camera(camera))


def render_member(engine, index: int, width: int = 480, height: int = 480,
                  camera: Mapping[str, Any] | None = None) -> np.ndarray:
    """Member ``index`` of an env engine's batch (``diffcloth_gym.envs.engine.ClothEngine``) as
    a (height, width, 3) uint8 RGB frame; the renderer is kept on the engine."""
    return _renderer(engine, width, height).render_member(engine.batch, index, _camera(camera))


def default_camera(sim, width: int = 480, height: int = 480) -> dict:
    """The camera :func:`render_rgb` uses when given none: a dict to modify and pass back."""
    return _renderer(sim, width, height).default_camera(sim._core)


def display_available() -> bool:
    """Whether a window can be opened (an X11 or Wayland display, or macOS / Windows)."""
    if sys.platform in ("darwin", "win32"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


class HumanViewer:
    """Shows frames in a matplotlib window, one ``show(frame)`` per step (``render_mode="human"``).

    Raises :class:`~diffcloth_gym.errors.UnsupportedError` where no display exists (headless:
    use ``rgb_array`` frames instead)."""

    def __init__(self, title: str = "diffcloth-gym", fps: float | None = None):
        from diffcloth_gym.errors import UnsupportedError

        if not display_available():
            raise UnsupportedError("render_mode='human' needs a display; headless, use render_mode='rgb_array'")
        import matplotlib.pyplot as plt  # optional, heavy: imported only for a window

        self._plt = plt
        self._pause = 1.0 / fps if fps else 1e-3
        self._fig, self._ax = plt.subplots(num=title)
        self._ax.set_axis_off()
        self._image = None
        plt.ion()

    def show(self, frame: np.ndarray) -> None:
        if self._image is None:
            self._image = self._ax.imshow(frame)
            self._fig.tight_layout()
        else:
            self._image.set_data(frame)
        self._plt.pause(self._pause)

    def close(self) -> None:
        self._plt.close(self._fig)
