"""Env rendering without OpenGL: ``render_mode="rgb_array"`` frames from the Rust rasterizer
(shape, dtype, they change as the cloth moves), the env checker's render check, and
Gymnasium's ``RecordVideo`` writing a video from them."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import diffcloth_gym  # noqa: F401
from diffcloth_gym.envs import ENVS

KWARGS = {"DiffCloth/FlyingNapkin-v0": {"resolution": 4}}


@pytest.mark.parametrize("env_id", sorted(ENVS))
def test_rgb_array_frames_show_the_motion(env_id):
    env = gym.make(env_id, render_mode="rgb_array", **KWARGS.get(env_id, {}))
    env.reset(seed=0)
    first = env.render()
    assert first.shape == (480, 480, 3) and first.dtype == np.uint8
    high = env.action_space.high
    for _ in range(15):
        env.step(high)
    last = env.render()
    changed = np.any(first != last, axis=-1).mean()
    assert changed > 0.002, f"only {changed:.2%} of the pixels changed"


@pytest.mark.parametrize("env_id", sorted(ENVS))
def test_env_checker_with_render(env_id):
    env = gym.make(env_id, render_mode="rgb_array", **KWARGS.get(env_id, {}))
    with pytest.warns(UserWarning):  # unbounded Box observations
        check_env(env.unwrapped)


def test_record_video_writes_a_video(tmp_path):
    pytest.importorskip("moviepy")
    env = gym.make("DiffCloth/FlyingNapkin-v0", render_mode="rgb_array", resolution=4)
    env = gym.wrappers.RecordVideo(env, str(tmp_path / "videos"), episode_trigger=lambda e: True, disable_logger=True)
    env.reset(seed=0)
    for _ in range(10):
        env.step(env.action_space.sample())
    env.close()
    videos = list((tmp_path / "videos").glob("*.mp4"))
    assert videos and videos[0].stat().st_size > 1000
