"""Every registered DiffCloth env (Gymnasium's own pattern, tests/envs/test_envs.py): the env
checker passes, seeded episodes are deterministic (also across thread counts and between the
vector env and single envs), random-action episodes stay finite, bad actions are refused with
the env usable afterwards, and ``step`` and ``step_grad`` are one simulation."""

import os
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest
import torch
from gymnasium.utils.env_checker import check_env

import diffcloth_gym
from diffcloth_gym.envs import ENVS
from diffcloth_gym.errors import InputError

#: Small variants keep CI fast; the physics and the plumbing are the same at full size.
KWARGS = {"DiffCloth/FlyingNapkin-v0": {"resolution": 4}}
IDS = sorted(ENVS)
#: Steps of the shorter checks (full episodes in test_random_episode_stays_finite).
SHORT = 6


def make(env_id, **kw):
    return gym.make(env_id, **{**KWARGS.get(env_id, {}), **kw}).unwrapped


def rollout(env, seed, steps, action_seed=0):
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(action_seed)
    out = [obs]
    for _ in range(steps):
        a = rng.uniform(env.action_space.low, env.action_space.high)
        obs, r, term, trunc, info = env.step(a)
        out += [obs, np.array([r])]
    return np.concatenate([np.ravel(o) for o in out])


@pytest.mark.parametrize("env_id", IDS)
def test_env_checker_passes(env_id):
    with pytest.warns(UserWarning):  # Gymnasium warns about unbounded Box observations
        check_env(make(env_id), skip_render_check=True)


@pytest.mark.parametrize("env_id", IDS)
def test_seeded_episodes_are_deterministic(env_id):
    a = rollout(make(env_id), seed=3, steps=SHORT)
    b = rollout(make(env_id), seed=3, steps=SHORT)
    c = rollout(make(env_id), seed=4, steps=SHORT)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c), "different seeds give different starts"


SCRIPT = """
import sys, numpy as np, gymnasium as gym, diffcloth_gym
sys.path.insert(0, {tests!r})
from test_envs import make, rollout
np.save(sys.argv[1], rollout(make({env_id!r}), seed=5, steps={steps}))
"""


@pytest.mark.parametrize("env_id", IDS)
def test_episodes_are_bitwise_equal_on_one_and_two_threads(env_id, tmp_path):
    results = []
    for threads in (1, 2):
        out = tmp_path / f"{threads}.npy"
        env = {**os.environ, "RAYON_NUM_THREADS": str(threads)}
        code = SCRIPT.format(tests=os.path.dirname(__file__), env_id=env_id, steps=SHORT)
        subprocess.run([sys.executable, "-c", code, str(out)], check=True, env=env)
        results.append(np.load(out))
    assert np.array_equal(*results)


@pytest.mark.parametrize("env_id", IDS)
def test_vector_env_members_equal_single_envs(env_id):
    n, seed = 3, 11
    venv = gym.make_vec(env_id, num_envs=n, **KWARGS.get(env_id, {}))
    obs, _ = venv.reset(seed=seed)
    singles = [make(env_id) for _ in range(n)]
    single_obs = [e.reset(seed=seed + i)[0] for i, e in enumerate(singles)]
    assert np.array_equal(obs, np.stack(single_obs))
    rng = np.random.default_rng(0)
    for _ in range(SHORT):
        actions = rng.uniform(venv.single_action_space.low, venv.single_action_space.high, (n, venv.single_action_space.shape[0]))
        obs, rew, *_ = venv.step(actions)
        for i, e in enumerate(singles):
            o, r, *_ = e.step(actions[i])
            assert np.array_equal(obs[i], o) and rew[i] == r


def vector_rollout(venv, seed, steps):
    obs, _ = venv.reset(seed=seed)
    rng = np.random.default_rng(0)
    space = venv.single_action_space
    out = [obs]
    for _ in range(steps):
        obs, rew, *_ = venv.step(rng.uniform(space.low, space.high, (venv.num_envs, space.shape[0])))
        out += [obs, rew]
    return np.concatenate([np.ravel(o) for o in out])


@pytest.mark.parametrize("env_id", IDS)
def test_vector_env_threads_argument_changes_speed_not_the_trajectory(env_id):
    runs = []
    for threads in (1, 2):
        venv = gym.make_vec(env_id, num_envs=3, threads=threads, **KWARGS.get(env_id, {}))
        assert venv.unwrapped.engine.batch.threads == threads
        runs.append(vector_rollout(venv, seed=2, steps=SHORT))
    assert np.array_equal(*runs)


@pytest.mark.parametrize("threads", [0, -1, 2.5, "2", 10**6])
def test_bad_thread_counts_are_refused_naming_the_argument(threads):
    with pytest.raises(InputError, match="threads"):
        gym.make_vec("DiffCloth/FlyingNapkin-v0", num_envs=2, threads=threads, resolution=4)


@pytest.mark.parametrize("env_id", IDS)
def test_vector_env_autoresets_on_the_next_step(env_id):
    venv = gym.make_vec(env_id, num_envs=2, **KWARGS.get(env_id, {}))
    # The plumbing does not depend on the horizon: a short one keeps the test fast.
    horizon = venv.unwrapped.task.horizon = 4
    venv.reset(seed=0)
    zero = np.zeros((2, venv.single_action_space.shape[0]))
    for k in range(horizon):
        obs, rew, term, trunc, info = venv.step(zero)
    assert trunc.all() and "success" in info
    obs, rew, term, trunc, info = venv.step(zero)
    assert not trunc.any() and np.all(rew == 0)
    assert venv.unwrapped.engine.batch.step_counts() == [0, 0]


@pytest.mark.parametrize("env_id", IDS)
def test_random_episode_stays_finite(env_id):
    env = make(env_id)
    env.reset(seed=7)
    for k in range(env.task.horizon):
        obs, r, term, trunc, info = env.step(env.action_space.sample())
        assert np.isfinite(obs).all() and np.isfinite(r), f"step {k}"
        assert "solver_error" not in info, info
    assert trunc and "success" in info


@pytest.mark.parametrize("env_id", IDS)
@pytest.mark.parametrize("bad", ["shape", "nan", "inf", "type"])
def test_bad_actions_are_refused_and_the_env_steps_on(env_id, bad):
    env, twin = make(env_id), make(env_id)
    env.reset(seed=1)
    twin.reset(seed=1)
    dim = env.action_space.shape[0]
    action = {"shape": np.zeros(dim + 1), "nan": np.full(dim, np.nan), "inf": np.full(dim, np.inf),
              "type": "left"}[bad]
    with pytest.raises(ValueError) as err:
        env.step(action)
    assert isinstance(err.value, diffcloth_gym.DiffClothError)
    good = np.full(dim, 0.5 * env.action_space.high)
    assert np.array_equal(env.step(good)[0], twin.step(good)[0])


@pytest.mark.parametrize("env_id", IDS)
def test_out_of_bounds_actions_are_clipped_and_counted(env_id):
    env, twin = make(env_id), make(env_id)
    env.reset(seed=2)
    twin.reset(seed=2)
    high = env.action_space.high
    obs, _, _, _, info = env.step(10 * high)
    assert info["action_clipped"] == env.action_space.shape[0]
    assert np.array_equal(obs, twin.step(high)[0])


@pytest.mark.parametrize("env_id", IDS)
def test_step_and_step_grad_give_the_same_next_state(env_id):
    env, twin = make(env_id), make(env_id)
    env.reset(seed=4)
    twin.reset(seed=4)
    rng = np.random.default_rng(1)
    for _ in range(3):
        a = rng.uniform(env.action_space.low, env.action_space.high)
        obs, r, *_ = env.step(a)
        obs_t, r_t, *_ = twin.step_grad(torch.from_numpy(a))
        assert np.array_equal(obs, obs_t.detach().numpy()) and r == r_t.item()


@pytest.mark.parametrize("env_id", IDS)
def test_mixing_step_and_step_grad_in_one_episode_is_refused(env_id):
    env = make(env_id)
    env.reset(seed=0)
    a = np.zeros(env.action_space.shape)
    env.step(a)
    with pytest.raises(InputError, match="not both"):
        env.step_grad(torch.from_numpy(a))
    env.reset(seed=0)
    env.step_grad(torch.from_numpy(a))
    with pytest.raises(InputError, match="not both"):
        env.step(a)


def test_env_torch_work_runs_on_one_thread_and_the_callers_setting_is_restored():
    env = make("DiffCloth/FlyingNapkin-v0")
    seen = []
    observe = env.task.observe
    env.task.observe = lambda *a: (seen.append(torch.get_num_threads()), observe(*a))[1]
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        env.reset(seed=0)
        env.step(env.action_space.sample())
        env.reset(seed=0)
        obs, reward, *_ = env.step_grad(torch.zeros(env.action_space.shape[0], dtype=torch.float64,
                                                    requires_grad=True))
        reward.backward()
        assert torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(before)
    assert seen == [1, 1, 1, 1]  # reset, step, reset, step_grad
