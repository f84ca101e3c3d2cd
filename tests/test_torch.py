"""torch.autograd through the simulator: gradcheck of a step, and a rollout's loss.backward()."""

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from diffcloth_gym import Simulator  # noqa: E402
from diffcloth_gym import torch as dtorch  # noqa: E402

CFG = {
    "h": 0.01,
    "effects": ["gravity", "stretch", "bend", "attachments", "external_forces", "obstacle_contact", "friction"],
    "mesh": {"kind": "grid", "rows": 3, "cols": 3, "width": 0.4, "height": 0.4, "plane": "xy"},
    "material": {"density": 0.2, "k_stretch": 50.0, "k_bend": 0.01},
    "attachments": {"stiffness": 300.0, "select": "top_corners"},
    # A plane far below: contact code paths run (detection), no contact becomes active.
    "obstacles": [{"mu": 0.3, "shape": {"kind": "plane", "point": [0, -5, 0], "normal": [0, 1, 0]}}],
    "solver": {"tolerance": 0.0, "max_iterations": 300},
}


def test_step_function_passes_gradcheck():
    sim = Simulator.from_config(CFG)
    n, k = sim.num_nodes, len(sim.attachment_nodes)
    gen = torch.Generator().manual_seed(0)
    x = torch.tensor(sim.positions, dtype=torch.float64) + 0.01 * torch.randn(n, 3, generator=gen, dtype=torch.float64)
    v = 0.1 * torch.randn(n, 3, generator=gen, dtype=torch.float64)
    targets = torch.tensor(sim.attachment_targets, dtype=torch.float64) + 0.02
    forces = 0.001 * torch.randn(n, 3, generator=gen, dtype=torch.float64)
    k_stretch = torch.tensor(50.0, dtype=torch.float64)
    inputs = [t.requires_grad_() for t in (x, v, targets, forces, k_stretch)]

    def f(x, v, targets, forces, k_stretch):
        return dtorch.step(sim, x, v, targets, forces, params={"k_stretch": k_stretch})

    assert torch.autograd.gradcheck(f, inputs, eps=1e-6, atol=1e-6, rtol=1e-4)


def test_rollout_loss_backward_matches_finite_differences():
    sim = Simulator.from_config(CFG)
    n = sim.num_nodes
    steps = 6
    x0 = torch.tensor(sim.positions, dtype=torch.float64)
    v0 = torch.zeros(n, 3, dtype=torch.float64, requires_grad=True)
    base = torch.tensor(sim.attachment_targets, dtype=torch.float64)
    targets = torch.stack([base + 0.01 * i for i in range(steps)]).requires_grad_()
    goal = x0 + torch.tensor([0.0, -0.05, 0.02], dtype=torch.float64)

    def loss_of(v0, targets):
        xs, vs = dtorch.rollout(sim, x0, v0, targets=targets)
        return ((xs - goal) ** 2).sum() + 0.1 * (vs[-1] ** 2).sum()

    loss = loss_of(v0, targets)
    loss.backward()
    d = torch.randn(targets.shape, generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    eps = 1e-5
    with torch.no_grad():
        fd = (loss_of(v0, targets + eps * d) - loss_of(v0, targets - eps * d)) / (2 * eps)
    analytic = (targets.grad * d).sum()
    assert abs(analytic - fd) <= 1e-5 * abs(fd)
    assert torch.isfinite(v0.grad).all()


def test_bad_inputs():
    sim = Simulator.from_config(CFG)
    x = torch.tensor(sim.positions)
    with pytest.raises(ValueError, match="float64"):
        dtorch.step(sim, x.float(), torch.zeros_like(x))
    with pytest.raises(ValueError, match="unknown"):
        dtorch.step(sim, x, torch.zeros_like(x), params={"stiffness": torch.tensor(1.0, dtype=torch.float64)})


def test_rollout_is_one_tape_and_matches_chained_steps():
    """The rollout Function (one tape, one adjoint pass) gives the gradients of the same
    rollout built from single-step Functions, also after the simulator was used in between
    (its backward then re-records the rollout) and through a checkpointed tape."""
    sim = Simulator.from_config(CFG)
    n, steps = sim.num_nodes, 5
    gen = torch.Generator().manual_seed(2)
    x0 = torch.tensor(sim.positions, dtype=torch.float64)
    base = torch.tensor(sim.attachment_targets, dtype=torch.float64)
    weights = torch.randn(steps, n, 3, generator=gen, dtype=torch.float64)

    def grads(run):
        v0 = (0.1 * torch.randn(n, 3, generator=torch.Generator().manual_seed(3), dtype=torch.float64)).requires_grad_()
        targets = torch.stack([base + 0.01 * i for i in range(steps)]).requires_grad_()
        k_bend = torch.tensor(0.01, dtype=torch.float64, requires_grad=True)
        xs, vs = run(v0, targets, k_bend)
        ((weights * xs).sum() + (vs[-1] ** 2).sum()).backward()
        return [v0.grad, targets.grad, k_bend.grad]

    def chained(v0, targets, k_bend):
        x, v, xs, vs = x0, v0, [], []
        for i in range(steps):
            x, v = dtorch.step(sim, x, v, targets[i], params={"k_bend": k_bend}, time=i * sim.params()["h"])
            xs.append(x)
            vs.append(v)
        return torch.stack(xs), torch.stack(vs)

    def interleaved(v0, targets, k_bend):
        out = dtorch.rollout(sim, x0, v0, targets=targets, params={"k_bend": k_bend})
        sim.reset()
        sim.step()
        return out

    reference = grads(chained)
    for run in (lambda *a: dtorch.rollout(sim, x0, *a[:2], params={"k_bend": a[2]}), interleaved,
                lambda *a: dtorch.rollout(sim, x0, *a[:2], params={"k_bend": a[2]}, checkpoint_every=2)):
        for got, ref in zip(grads(run), reference):
            assert torch.allclose(got, ref, rtol=1e-8, atol=1e-12), (got, ref)
