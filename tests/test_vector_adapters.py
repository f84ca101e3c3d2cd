"""The vector adapters over one batch: SB3's PPO trains on the SB3 ``VecEnv`` directly (same-step
reset with ``terminal_observation`` and ``TimeLimit.truncated``), and both adapters agree with
single envs seeded alike."""

import gymnasium as gym
import numpy as np
import pytest

import diffcloth_gym  # noqa: F401
from diffcloth_gym.envs.sb3 import ClothSB3VecEnv

NAPKIN = {"resolution": 4}


def test_sb3_vec_env_resets_in_the_same_step_with_the_terminal_observation():
    venv = ClothSB3VecEnv("DiffCloth/FlyingNapkin-v0", num_envs=2, **NAPKIN)
    venv.task.horizon = 3  # the plumbing, not the task, is under test
    venv.seed(5)
    obs = venv.reset()
    single = gym.make("DiffCloth/FlyingNapkin-v0", **NAPKIN).unwrapped
    assert np.array_equal(obs[1], single.reset(seed=6)[0])
    zero = np.zeros((2, venv.action_space.shape[0]))
    for _ in range(3):
        obs, rew, dones, infos = venv.step(zero)
    assert dones.all()
    for info in infos:
        assert info["TimeLimit.truncated"] and info["terminal_observation"].shape == obs[0].shape
        assert not np.array_equal(info["terminal_observation"], obs[0])
    assert venv.engine.batch.step_counts() == [0, 0]


def test_ppo_trains_on_the_sb3_adapter():
    pytest.importorskip("stable_baselines3")
    from stable_baselines3 import PPO

    venv = ClothSB3VecEnv("DiffCloth/FlyingNapkin-v0", num_envs=2, **NAPKIN)
    model = PPO("MlpPolicy", venv, n_steps=16, batch_size=16, n_epochs=1, seed=0, device="cpu")
    model.learn(total_timesteps=64)
    assert model.num_timesteps == 64
    action, _ = model.predict(venv.reset(), deterministic=True)
    assert action.shape == (2, venv.action_space.shape[0])
