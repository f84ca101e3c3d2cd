"""``step_grad``: the gradient of a closed-loop return through the Rust adjoint matches central
finite differences (float64, forward converged far below the step), with respect to a
policy's parameters (FlyingNapkin; Hat in test_hat_env.py) and to the actions (Sock). Errors
are measured against the gradient's largest entry, on the largest entries and a random few."""

import gymnasium as gym
import numpy as np
import pytest
import torch

import diffcloth_gym  # noqa: F401  (registers the envs)
from diffcloth_gym.errors import InputError

#: Forward tolerance of the FD runs: far below eps times the return's sensitivity.
TIGHT = {"tolerance": 1e-13, "max_iterations": 5000}


def closed_loop_return(env, policy, seed, steps):
    """Sum of step_grad rewards under ``policy`` (a torch module on the observation)."""
    obs, _ = env.reset(seed=seed)
    obs = torch.from_numpy(obs)
    total = torch.zeros((), dtype=torch.float64)
    for _ in range(steps):
        obs, r, *_ = env.step_grad(policy(obs))
        total = total + r
    return total


def plain_return(env, policy, seed, steps):
    obs, _ = env.reset(seed=seed)
    total = 0.0
    with torch.no_grad():
        for _ in range(steps):
            obs, r, *_ = env.step(policy(torch.from_numpy(obs)).numpy())
            total += r
    return total


def probe_indices(grad: np.ndarray, rng, k_top=3, k_random=3):
    order = np.argsort(-np.abs(grad).ravel())
    return sorted(set(order[:k_top]) | set(rng.choice(grad.size, k_random, replace=False)))


def check_fd(loss_at, theta: np.ndarray, grad: np.ndarray, eps: float, tol: float):
    """Central differences of ``loss_at`` at a few coordinates of ``theta`` vs ``grad``."""
    rng = np.random.default_rng(0)
    scale = np.abs(grad).max()
    assert scale > 0, "a zero gradient checks nothing"
    worst = 0.0
    for i in probe_indices(grad, rng):
        e = np.zeros_like(theta)
        e.flat[i] = eps
        fd = (loss_at(theta + e) - loss_at(theta - e)) / (2 * eps)
        worst = max(worst, abs(fd - grad.flat[i]) / scale)
    assert worst < tol, f"FD error {worst:.2e} of the largest entry {scale:.2e}"


class LinearTanh(torch.nn.Module):
    """A small policy: tanh(W obs + b), scaled to the action bound."""

    def __init__(self, obs_dim, act_dim, bound, seed=0):
        super().__init__()
        g = torch.Generator().manual_seed(seed)
        # Scaled by 1/sqrt(obs_dim) so tanh is not saturated (a saturated policy has a
        # vanishing gradient that finite differences cannot resolve).
        w = torch.randn(act_dim, obs_dim, generator=g, dtype=torch.float64) * 0.05 / obs_dim**0.5
        self.w = torch.nn.Parameter(w)
        self.b = torch.nn.Parameter(0.1 * torch.randn(act_dim, generator=g, dtype=torch.float64))
        self.bound = bound

    def forward(self, obs):
        return self.bound * torch.tanh(self.w @ obs + self.b)

    def flat(self):
        return torch.cat([self.w.detach().ravel(), self.b.detach()]).numpy()

    def set_flat(self, theta):
        n = self.w.numel()
        with torch.no_grad():
            self.w.copy_(torch.from_numpy(theta[:n]).reshape(self.w.shape))
            self.b.copy_(torch.from_numpy(theta[n:]))


def check_policy_gradient(env, policy, steps=20):
    """The gradient of a ``steps``-step closed-loop return w.r.t. ``policy``'s parameters
    through ``step_grad`` vs central differences of plain-step returns."""
    total = closed_loop_return(env, policy, seed=0, steps=steps)
    total.backward()
    grad = torch.cat([policy.w.grad.ravel(), policy.b.grad]).numpy()
    theta = policy.flat()

    def loss_at(t):
        policy.set_flat(t)
        return plain_return(env, policy, seed=0, steps=steps)

    assert loss_at(theta) == total.item(), "step and step_grad are one simulation"
    check_fd(loss_at, theta, grad, eps=1e-5, tol=1e-5)


def test_flying_napkin_policy_gradient_matches_finite_differences():
    env = gym.make("DiffCloth/FlyingNapkin-v0", resolution=4, solver=TIGHT).unwrapped
    check_policy_gradient(env, LinearTanh(env.task.obs_dim, env.task.action_dim, 0.5 * env.task.action_bound))


def test_sock_action_gradient_matches_finite_differences():
    env = gym.make("DiffCloth/Sock-v0", solver=TIGHT).unwrapped
    steps = 20
    rng = np.random.default_rng(3)
    actions = 0.3 * rng.uniform(-1, 1, (steps, env.task.action_dim)) * env.task.action_bound
    a = torch.tensor(actions, requires_grad=True)
    env.reset(seed=0)
    total = sum(env.step_grad(a[k])[1] for k in range(steps))
    total.backward()
    grad = a.grad.numpy()

    def loss_at(acts):
        env.reset(seed=0)
        return sum(env.step(acts[k])[1] for k in range(steps))

    check_fd(loss_at, actions, grad, eps=1e-5, tol=1e-5)


def test_backward_after_reset_is_refused():
    env = gym.make("DiffCloth/FlyingNapkin-v0", resolution=4).unwrapped
    env.reset(seed=0)
    a = torch.zeros(env.task.action_dim, dtype=torch.float64, requires_grad=True)
    _, r, *_ = env.step_grad(a)
    env.reset(seed=0)
    with pytest.raises(InputError, match="reset before backward"):
        r.backward()


def test_step_grad_needs_a_float64_tensor():
    env = gym.make("DiffCloth/FlyingNapkin-v0", resolution=4).unwrapped
    env.reset(seed=0)
    with pytest.raises(InputError, match="float64"):
        env.step_grad(torch.zeros(env.task.action_dim, dtype=torch.float32))
    # Still usable.
    env.step_grad(torch.zeros(env.task.action_dim, dtype=torch.float64))


def test_consecutive_differentiable_episodes_have_separate_graphs():
    env = gym.make("DiffCloth/FlyingNapkin-v0", resolution=4).unwrapped
    grads = []
    for _ in range(2):
        env.reset(seed=0)
        a = torch.full((env.task.action_dim,), 0.1, dtype=torch.float64, requires_grad=True)
        total = sum(env.step_grad(a)[1] for _ in range(3))
        total.backward()
        grads.append(a.grad.clone())
    assert torch.equal(grads[0], grads[1])
