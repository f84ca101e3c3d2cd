"""Hat-v0 end to end: a random policy from each of the 20 test starts runs the whole episode
without NaN and without the hat entering the head, and the closed-loop policy gradient
through ``step_grad`` matches central finite differences."""

import gymnasium as gym
import numpy as np

import diffcloth_gym  # noqa: F401
from diffcloth_gym.envs.hat_v0 import TEST_STARTS, head_sphere
from tests.test_step_grad import TIGHT, LinearTanh, check_policy_gradient

#: The contact layer's thickness (the core's default, `contact.thickness`).
THICKNESS = 0.01


def test_a_random_policy_from_every_test_start_stays_finite_and_out_of_the_head():
    venv = gym.make_vec("DiffCloth/Hat-v0", num_envs=len(TEST_STARTS))
    engine = venv.unwrapped.engine
    centre, radius = head_sphere(engine.scene)
    obs, _ = venv.reset(seed=0, options={"starts": TEST_STARTS})
    rng = np.random.default_rng(0)
    deepest = np.inf
    for k in range(engine.task.horizon):
        actions = rng.uniform(-1, 1, (len(TEST_STARTS), engine.task.action_dim))
        obs, reward, term, trunc, info = venv.step(actions)
        assert np.isfinite(obs).all() and np.isfinite(reward).all(), f"step {k}"
        assert "solver_error" not in info, info.get("solver_error")
        x = engine.batch.positions()
        deepest = min(deepest, float((np.linalg.norm(x - centre, axis=-1) - radius).min()))
    assert trunc.all()
    assert deepest > -THICKNESS, f"a node went {-deepest:.4f} into the head"


def test_hat_policy_gradient_through_step_grad_matches_finite_differences():
    env = gym.make("DiffCloth/Hat-v0", solver=TIGHT).unwrapped
    check_policy_gradient(env, LinearTanh(env.task.obs_dim, env.task.action_dim, 0.5, seed=1))
