"""The software renderer (rust/diffcloth-render through diffcloth_gym.rendering): frames of the
right shape and type, showing the cloth, the obstacles and the effectors, changing with the
state, deterministic, and refusing bad arguments with errors naming them."""

import numpy as np
import pytest

from diffcloth_gym import InputError, Simulator, UnsupportedError, contact_free, load_scene
from diffcloth_gym import rendering
from diffcloth_gym._core import Renderer


def cloth_mask(frame):
    """Pixels of the cloth's front (red) or back (ochre) side: red well above blue."""
    f = frame.astype(int)
    return (f[..., 0] - f[..., 2] > 60)


def marker_mask(frame):
    """Pixels of the effector marks (green)."""
    f = frame.astype(int)
    return (f[..., 1] > 150) & (f[..., 0] < 90) & (f[..., 1] - f[..., 2] > 40)


def project(camera, points, width, height):
    """Pixel coordinates of scene points seen by a camera dict (the renderer's pinhole model)."""
    eye, target, up = (np.asarray(camera[k], float) for k in ("eye", "target", "up"))
    back = (eye - target) / np.linalg.norm(eye - target)
    right = np.cross(up, back)
    right /= np.linalg.norm(right)
    true_up = np.cross(back, right)
    rel = np.asarray(points, float) - eye
    x, y, depth = rel @ right, rel @ true_up, -(rel @ back)
    scale = height / 2 / np.tan(np.radians(camera["fov"]) / 2)
    return np.stack([width / 2 + scale * x / depth, height / 2 - scale * y / depth], axis=-1)


@pytest.fixture(scope="module")
def hat():
    return Simulator.from_config("hat")


def test_frame_shape_and_type(hat):
    for w, h in [(480, 480), (200, 120), (1, 1)]:
        frame = hat.render(w, h)
        assert frame.shape == (h, w, 3) and frame.dtype == np.uint8
        assert frame.flags["C_CONTIGUOUS"] and frame.flags["WRITEABLE"]


def test_the_cloth_is_drawn_where_it_projects(hat):
    frame = hat.render(480, 480)
    camera = rendering.default_camera(hat, 480, 480)
    # The hat's crown (its highest nodes) projects onto cloth-coloured pixels.
    x = hat.positions
    crown = x[x[:, 1] > np.percentile(x[:, 1], 90)].mean(axis=0)
    px, py = np.round(project(camera, crown, 480, 480)).astype(int)
    assert cloth_mask(frame)[py, px], frame[py, px]
    assert cloth_mask(frame).sum() > 2000
    # Everything the renderer frames by default is inside the frame.
    uv = project(camera, x, 480, 480)
    assert (uv > 0).all() and (uv < 480).all()


def test_frames_change_as_the_napkin_falls():
    sim = Simulator.from_config("napkin")
    first = sim.render(240, 240)
    sim.step(steps=50)
    later = sim.render(240, 240)
    changed = np.any(first != later, axis=-1)
    assert changed.mean() > 0.02
    # Same camera for both frames (the framing does not follow the cloth): the cloth moved down.
    rows_first = np.nonzero(cloth_mask(first).any(axis=1))[0]
    rows_later = np.nonzero(cloth_mask(later).any(axis=1))[0]
    assert rows_later.mean() > rows_first.mean() + 5


def test_obstacles_are_drawn():
    with_sphere = Simulator.from_config("sphere")
    without = Simulator.from_config(contact_free(load_scene("sphere")))
    camera = rendering.default_camera(with_sphere, 240, 240)
    a, b = with_sphere.render(240, 240, camera), without.render(240, 240, camera)
    # The sphere (radius 2 at the origin) covers its projected centre and changes a large area.
    cx, cy = np.round(project(camera, [0.0, 0.0, 0.0], 240, 240)).astype(int)
    assert np.any(a[cy, cx] != b[cy, cx])
    assert np.any(a != b, axis=-1).mean() > 0.05


@pytest.mark.parametrize("scene", ["slope", "bowl", "pyramid", "sock"])
def test_every_obstacle_kind_renders(scene):
    sim = Simulator.from_config(scene)
    free = Simulator.from_config(contact_free(load_scene(scene)))
    camera = rendering.default_camera(sim, 160, 160)
    assert np.any(sim.render(160, 160, camera) != free.render(160, 160, camera), axis=-1).mean() > 0.02


def test_moving_obstacles_are_drawn_where_they_are_now():
    cfg = load_scene("sphere")
    cfg["obstacles"][0]["velocity"] = [1.0, 0.0, 0.0]
    sim = Simulator.from_config(cfg)
    before = sim.render(160, 160)
    sim.time = 1.0
    after = sim.render(160, 160)
    assert np.any(before != after, axis=-1).mean() > 0.02


def test_effectors_are_marked(hat):
    marks = marker_mask(hat.render(480, 480))
    assert marks.sum() > 20
    camera = rendering.default_camera(hat, 480, 480)
    for px, py in np.round(project(camera, hat.attachment_targets, 480, 480)).astype(int):
        assert marks[py - 2:py + 3, px - 2:px + 3].any(), (px, py)
    # A scene without attachments has no marks.
    assert not marker_mask(Simulator.from_config("napkin").render(240, 240)).any()


def test_frames_are_deterministic():
    sims = [Simulator.from_config("hat") for _ in range(2)]
    for sim in sims:
        sim.step(steps=5)
    first = sims[0].render(320, 240)
    assert np.array_equal(first, sims[0].render(320, 240))
    assert np.array_equal(first, sims[1].render(320, 240))
    # A fresh renderer of the same size gives the same frame.
    assert np.array_equal(first, Renderer(320, 240).render(sims[0]._core))


def test_the_camera_can_be_set(hat):
    default = rendering.default_camera(hat, 240, 240)
    assert set(default) == {"eye", "target", "up", "fov"}
    assert np.array_equal(hat.render(240, 240), hat.render(240, 240, default))
    top = dict(default, eye=[0.0, 20.0, 0.1], fov=30.0)
    assert not np.array_equal(hat.render(240, 240), hat.render(240, 240, top))
    # Partial dicts take the rest from the default; numpy arrays are accepted.
    narrow = hat.render(240, 240, {"fov": 20.0, "target": np.array(default["target"])})
    assert np.array_equal(narrow, hat.render(240, 240, dict(default, fov=20.0)))


@pytest.mark.parametrize("width, height, name", [
    (0, 10, "width"), (10, 0, "height"), (5000, 10, "width"), (10, 10**6, "height"),
    (-1, 10, "width"), ("wide", 10, "width"), (10, 2.5, "height"),
])
def test_bad_sizes_raise_naming_the_argument(hat, width, height, name):
    with pytest.raises(InputError, match=name):
        hat.render(width, height)


@pytest.mark.parametrize("camera, name", [
    ({"eye": [np.nan, 0.0, 0.0]}, "camera.eye"),
    ({"target": [0.0, np.inf, 0.0]}, "camera.target"),
    ({"eye": [1.0, 2.0]}, "camera.eye"),
    ({"up": "up"}, "camera.up"),
    ({"up": [0.0, 0.0, 0.0]}, "camera.up"),
    ({"fov": 0.0}, "camera.fov"),
    ({"fov": float("nan")}, "camera.fov"),
    ({"fov": "wide"}, "camera.fov"),
    ({"eye": [0.0, 0.0, 0.0], "target": [0.0, 0.0, 0.0]}, "camera.eye"),
    ({"position": [0.0, 0.0, 1.0]}, "position"),
    ([0.0, 0.0, 1.0], "camera"),
])
def test_bad_cameras_raise_naming_the_entry(hat, camera, name):
    with pytest.raises(InputError, match=name):
        hat.render(64, 64, camera)
    assert hat.render(64, 64).shape == (64, 64, 3), "still usable"


def test_human_mode_needs_a_display(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr(rendering.sys, "platform", "linux")
    with pytest.raises(UnsupportedError, match="display"):
        rendering.HumanViewer()
