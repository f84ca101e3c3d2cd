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


def _gymnasium_infos(venv, r, live):
    """What Gymnasium's own ``VectorEnv._add_info`` builds from the live members' info dicts."""
    infos = {}
    for i in np.flatnonzero(live):
        infos = venv._add_info(infos, r.info(i), int(i))
    return infos


def test_vector_infos_equal_gymnasiums_merge_of_the_members_infos():
    from diffcloth_gym.envs.vector import vector_infos

    venv = gym.make_vec("DiffCloth/FlyingNapkin-v0", num_envs=3, **NAPKIN).unwrapped
    venv.task.horizon = 2
    venv.reset(seed=0)
    engine = venv.engine
    bound = venv.single_action_space.high
    # Member 1 over the bounds (clipped entries counted), then the horizon (success extras), then
    # member 0 starting over while the others step (not live in this step's infos).
    for k, live in enumerate([[1, 1, 1], [1, 1, 1], [0, 1, 1]]):
        a = np.zeros((3, venv.single_action_space.shape[0]))
        a[1, :4] = 3 * bound[:4]
        if k == 2:
            engine.reset([0], [venv.task.sample_start(np.random.default_rng(1))])
        r = engine.step(a)
        live = np.array(live, dtype=bool)
        got, want = vector_infos(r, live), _gymnasium_infos(venv, r, live)
        assert list(got) == list(want)
        for key in want:
            assert got[key].dtype == want[key].dtype and np.array_equal(got[key], want[key]), key
        assert got["action_clipped"].tolist() == [0, 4 * live[1], 0]
    assert "success" in want and want["_success"].tolist() == [False, True, True]


def test_vector_env_step_counts_clipped_action_entries():
    venv = gym.make_vec("DiffCloth/FlyingNapkin-v0", num_envs=2, **NAPKIN)
    venv.reset(seed=0)
    a = np.zeros((2, venv.single_action_space.shape[0]))
    a[0, :5] = 2.0
    *_, infos = venv.step(a)
    assert infos["action_clipped"].tolist() == [5, 0]
