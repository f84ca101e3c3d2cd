"""PyTorch autograd through the simulator (float64).

``step(sim, x, v, targets=None, forces=None, params=None)`` advances one implicit-Euler step
and returns ``(x_next, v_next)`` as tensors whose graph runs through the Rust adjoint (contact
included); ``rollout`` chains steps, so ``loss.backward()`` works on losses built from any
steps' states. Gradients flow to ``x``, ``v``, the attachment ``targets`` (the actions), the
per-node ``forces`` and the physical parameters given in ``params``, by the names
``Simulator.params()`` uses (``PARAM_NAMES``: ``k_stretch``, ``k_bend``, ``k_attach``,
``density``, ``wind_omega``, ``wind_phi``, ``mu_self`` scalars; ``gravity``,
``wind_direction`` 3-vectors; ``mu_obstacles`` one entry per obstacle). Nothing is clipped.

Steps run at the simulator's solver settings, recorded or not: for gradients set
``sim.set_solver(preset="gradient")`` first (the backward warns when the recorded steps are
too loose).

``rollout`` is one autograd node: its forward records the whole rollout on the simulator's
tape (optionally checkpointed) and its backward runs one adjoint pass over it, warm-started
from step to step, with no second forward. If the simulator was used in between (its tape
changed), the backward first re-records the rollout from the saved inputs (deterministic).
The backward of a single ``step`` re-simulates that step with a one-step tape.
"""

from __future__ import annotations

import numpy as np
import torch

from diffcloth_gym import _core
from diffcloth_gym.simulator import Simulator

#: The differentiable physical parameters (the core's name table, shared with set_params and backward).
PARAM_NAMES = tuple(_core.PARAM_NAMES)


def _np(t: torch.Tensor | None) -> np.ndarray | None:
    return None if t is None else t.detach().cpu().numpy().astype(np.float64)


def _simulate(sim: Simulator, x, v, targets, forces, params: dict, time: float, record: bool):
    if params:
        sim.set_params(**params)
    sim.set_recording(record)
    sim.reset(x=x, v=v)
    sim.time = time
    sim.step(attachment_targets=targets, external_forces=forces)
    return sim.positions, sim.velocities


class StepFunction(torch.autograd.Function):
    """One step as an autograd function. Inputs: sim, time, param names, x, v, targets,
    forces, then one tensor per named parameter."""

    @staticmethod
    def forward(ctx, sim, time, names, x, v, targets, forces, *values):
        params = {k: _np(t).tolist() if t.dim() else float(t) for k, t in zip(names, values)}
        xn, vn = _simulate(sim, _np(x), _np(v), _np(targets), _np(forces), params, time, record=False)
        ctx.sim, ctx.time, ctx.names, ctx.params = sim, time, names, params
        ctx.has_targets, ctx.has_forces = targets is not None, forces is not None
        ctx.save_for_backward(x, v, targets if targets is not None else x.new_empty(0), forces if forces is not None else x.new_empty(0))
        return torch.from_numpy(xn).to(x), torch.from_numpy(vn).to(x)

    @staticmethod
    def backward(ctx, gx, gv):
        x, v, targets, forces = ctx.saved_tensors
        sim = ctx.sim
        _simulate(sim, _np(x), _np(v), _np(targets) if ctx.has_targets else None,
                  _np(forces) if ctx.has_forces else None, ctx.params, ctx.time, record=True)
        g = sim.backward(dl_dx=_np(gx)[None], dl_dv=_np(gv)[None], solver="krylov", tolerance=1e-12)
        sim.set_recording(False)
        _warn(g)
        as_t = lambda a: torch.as_tensor(np.asarray(a), dtype=x.dtype, device=x.device)  # noqa: E731
        grads = [None, None, None, as_t(g["x0"]), as_t(g["v0"])]
        grads.append(as_t(g["attachment_targets"][0]) if ctx.has_targets else None)
        grads.append(as_t(g["external_forces"][0]) if ctx.has_forces else None)
        grads += [as_t(g[name]) for name in ctx.names]
        return tuple(grads)


def _warn(g: dict) -> None:
    if g["warnings"]:
        import warnings

        for w in g["warnings"]:
            warnings.warn(f"diffcloth gradient: {w}", stacklevel=3)


def _record_rollout(sim: Simulator, x0, v0, targets, forces, params: dict, steps: int, checkpoint_every):
    if params:
        sim.set_params(**params)
    sim.reset(x=x0, v=v0)
    sim.set_recording(True, checkpoint_every)
    xs, vs = [], []
    for n in range(steps):
        sim.step(attachment_targets=None if targets is None else targets[n],
                 external_forces=None if forces is None else forces[n])
        xs.append(sim.positions)
        vs.append(sim.velocities)
    return np.stack(xs), np.stack(vs)


class RolloutFunction(torch.autograd.Function):
    """A whole rollout as one autograd function (one tape, one adjoint pass). Inputs: sim,
    steps, checkpoint_every, param names, x0, v0, targets (T, k, 3), forces (T, n, 3), then
    one tensor per named parameter."""

    @staticmethod
    def forward(ctx, sim, steps, checkpoint_every, names, x0, v0, targets, forces, *values):
        params = {k: _np(t).tolist() if t.dim() else float(t) for k, t in zip(names, values)}
        inputs = (_np(x0), _np(v0), _np(targets), _np(forces))
        xs, vs = _record_rollout(sim, *inputs, params, steps, checkpoint_every)
        ctx.sim, ctx.steps, ctx.checkpoint_every, ctx.names, ctx.params = sim, steps, checkpoint_every, names, params
        ctx.inputs, ctx.tape_version = inputs, sim._tape_version
        ctx.has_targets, ctx.has_forces = targets is not None, forces is not None
        return torch.from_numpy(xs).to(x0), torch.from_numpy(vs).to(x0)

    @staticmethod
    def backward(ctx, gxs, gvs):
        sim = ctx.sim
        if sim._tape_version != ctx.tape_version:
            _record_rollout(sim, *ctx.inputs, ctx.params, ctx.steps, ctx.checkpoint_every)
            ctx.tape_version = sim._tape_version
        g = sim.backward(dl_dx=_np(gxs), dl_dv=_np(gvs), solver="krylov", tolerance=1e-12)
        _warn(g)
        like = gxs
        as_t = lambda a: torch.as_tensor(np.asarray(a), dtype=like.dtype, device=like.device)  # noqa: E731
        grads = [None, None, None, None, as_t(g["x0"]), as_t(g["v0"])]
        grads.append(as_t(np.stack(g["attachment_targets"])) if ctx.has_targets else None)
        grads.append(as_t(np.stack(g["external_forces"])) if ctx.has_forces else None)
        grads += [as_t(g[name]) for name in ctx.names]
        return tuple(grads)


def _check_inputs(params: dict, tensors) -> tuple:
    unknown = set(params) - set(PARAM_NAMES)
    if unknown:
        raise ValueError(f"unknown differentiable parameters {sorted(unknown)}; known: {PARAM_NAMES}")
    for name, t in [*tensors, *params.items()]:
        if t is not None and t.dtype != torch.float64:
            raise ValueError(f"{name} must be float64 (the simulator and its gradients are double precision)")
    return tuple(params)


def step(sim: Simulator, x: torch.Tensor, v: torch.Tensor, targets: torch.Tensor | None = None,
         forces: torch.Tensor | None = None, params: dict | None = None, time: float = 0.0):
    """One differentiable step from state ``(x, v)`` at simulated ``time``; returns
    ``(x_next, v_next)``. ``params`` maps parameter names to float64 tensors (scalars,
    3-vectors for ``gravity`` and ``wind_direction``, one entry per obstacle for
    ``mu_obstacles``)."""
    params = params or {}
    names = _check_inputs(params, [("x", x), ("v", v), ("targets", targets), ("forces", forces)])
    return StepFunction.apply(sim, float(time), names, x, v, targets, forces, *[params[k] for k in names])


def rollout(sim: Simulator, x0: torch.Tensor, v0: torch.Tensor, targets: torch.Tensor | None = None,
            forces: torch.Tensor | None = None, params: dict | None = None, steps: int | None = None,
            checkpoint_every: int | None = None):
    """``steps`` differentiable steps from ``(x0, v0)`` at time 0 (default: the length of
    ``targets``/``forces``); ``targets`` (T, k, 3) and ``forces`` (T, n, 3) give each step's
    inputs. Returns the positions and velocities after every step, each (T, n, 3).

    One tape and one adjoint pass for the whole rollout (``checkpoint_every=K`` keeps only
    every K-th state: memory bounded, backward re-simulates segments). The simulator is left
    at the rollout's end state, with the tape recording."""
    if steps is None:
        lengths = {len(a) for a in (targets, forces) if a is not None}
        if len(lengths) != 1:
            raise ValueError("give `steps`, or targets/forces with one entry per step")
        steps = lengths.pop()
    for name, a in (("targets", targets), ("forces", forces)):
        if a is not None and len(a) != steps:
            raise ValueError(f"{name} has {len(a)} entries for {steps} steps")
    params = params or {}
    names = _check_inputs(params, [("x0", x0), ("v0", v0), ("targets", targets), ("forces", forces)])
    return RolloutFunction.apply(sim, int(steps), checkpoint_every, names, x0, v0, targets, forces,
                                 *[params[k] for k in names])
