"""PyTorch autograd through the simulator (float64).

``step(sim, x, v, targets=None, forces=None, params=None)`` advances one implicit-Euler step
and returns ``(x_next, v_next)`` as tensors whose graph runs through the Rust adjoint (contact
included); ``rollout`` chains steps, so ``loss.backward()`` works on losses built from any
steps' states. Gradients flow to ``x``, ``v``, the attachment ``targets`` (the actions), the
per-node ``forces`` and the scalar/vector physical parameters given in ``params``
(``k_stretch``, ``k_bend``, ``k_attach``, ``density``, ``wind_omega``, ``wind_phi``,
``gravity``, ``wind_direction``). Nothing is clipped.

The backward of a step re-simulates that step from its saved inputs with a one-step tape
(deterministic), so memory does not grow with the horizon beyond the states autograd keeps.
"""

from __future__ import annotations

import numpy as np
import torch

from diffcloth_gym.simulator import Simulator

PARAM_NAMES = ("k_stretch", "k_bend", "k_attach", "density", "wind_omega", "wind_phi", "gravity", "wind_direction")


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
        if g["warnings"]:
            import warnings

            for w in g["warnings"]:
                warnings.warn(f"diffcloth gradient: {w}", stacklevel=2)
        as_t = lambda a: torch.as_tensor(np.asarray(a), dtype=x.dtype, device=x.device)  # noqa: E731
        grads = [None, None, None, as_t(g["x0"]), as_t(g["v0"])]
        grads.append(as_t(g["attachment_targets"][0]) if ctx.has_targets else None)
        grads.append(as_t(g["external_forces"][0]) if ctx.has_forces else None)
        grads += [as_t(g[name]) for name in ctx.names]
        return tuple(grads)


def step(sim: Simulator, x: torch.Tensor, v: torch.Tensor, targets: torch.Tensor | None = None,
         forces: torch.Tensor | None = None, params: dict | None = None, time: float = 0.0):
    """One differentiable step from state ``(x, v)`` at simulated ``time``; returns
    ``(x_next, v_next)``. ``params`` maps parameter names to float64 tensors (scalars, or
    3-vectors for ``gravity`` and ``wind_direction``)."""
    params = params or {}
    unknown = set(params) - set(PARAM_NAMES)
    if unknown:
        raise ValueError(f"unknown differentiable parameters {sorted(unknown)}; known: {PARAM_NAMES}")
    for name, t in [("x", x), ("v", v), ("targets", targets), ("forces", forces), *params.items()]:
        if t is not None and t.dtype != torch.float64:
            raise ValueError(f"{name} must be float64 (the simulator and its gradients are double precision)")
    names = tuple(params)
    return StepFunction.apply(sim, float(time), names, x, v, targets, forces, *[params[k] for k in names])


def rollout(sim: Simulator, x0: torch.Tensor, v0: torch.Tensor, targets: torch.Tensor | None = None,
            forces: torch.Tensor | None = None, params: dict | None = None, steps: int | None = None):
    """Chains ``steps`` differentiable steps (default: the length of ``targets``/``forces``);
    ``targets`` (T, k, 3) and ``forces`` (T, n, 3) give each step's inputs. Returns the
    positions and velocities after every step, each (T, n, 3)."""
    if steps is None:
        lengths = {len(a) for a in (targets, forces) if a is not None}
        if len(lengths) != 1:
            raise ValueError("give `steps`, or targets/forces with one entry per step")
        steps = lengths.pop()
    h = sim.params()["h"]
    x, v, xs, vs = x0, v0, [], []
    for n in range(steps):
        x, v = step(sim, x, v, None if targets is None else targets[n], None if forces is None else forces[n], params, time=n * h)
        xs.append(x)
        vs.append(v)
    return torch.stack(xs), torch.stack(vs)
