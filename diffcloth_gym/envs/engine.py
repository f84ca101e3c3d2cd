"""The plumbing every cloth env shares, batched: N members of one task on a Rust
``_core.Batch`` (one shared model and factorization, stepped in parallel without the GIL).
The single env is a batch of one and the vector envs are adapters over it, so a vector env's
member i and a single env seeded alike run bitwise the same simulation.

One accuracy rule: the solver's plain and recorded tolerances (and iteration caps) are set
equal, so ``step`` and ``step_grad`` from the same state and action give the same next state;
a gradient is a matter of recording the step, not of simulating it differently.

Threads: the simulator's steps run on rayon threads; the engine's own torch work (actions,
observations, rewards: small tensors) runs on one torch thread whatever the caller's
``torch.get_num_threads()`` (restored afterwards). Measured on 2 cores, torch's second
intra-op thread competed with rayon's for the cores: a 32-member FlyingNapkin step's Python
part took 18 ms instead of 1 ms and its Rust step 48 ms instead of 32.
"""

from __future__ import annotations

import copy
import functools
import json
from dataclasses import dataclass, field
from typing import Any, Mapping, NamedTuple

import numpy as np
import torch

from diffcloth_gym import _core
from diffcloth_gym.envs.task import ClothTask, Start
from diffcloth_gym.errors import InputError, ParameterError
from diffcloth_gym.scenes import load_config
from diffcloth_gym.simulator import Simulator

#: Default PD tolerance of env steps (RMS update, scene units): below the residual the
#: adjoint trusts (1e-9), so every step is gradient-grade.
DEFAULT_TOLERANCE = 1e-10
#: Default iteration cap of env steps. A Hat step with slipping contacts can sit near a saddle
#: for thousands of PD iterations before it converges; at a cap of 2000 such steps stopped
#: above the tolerance and, alone, made the Hat's 400-step gradient 1.2e-2 off a 1e-13 one
#: (`benchmarks/gradient_cost.py`'s case: 5 such steps; 1.3e-6 with all converged, same time).
#: Measured there and under random effector motion, those steps converged after 2000-3740
#: iterations, one after 5000-10000; a step that does not converge at all costs the cap.
DEFAULT_MAX_ITERATIONS = 10000


def single_threaded_torch(fn):
    """Runs ``fn`` with torch on one intra-op thread (see the module docstring)."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        threads = torch.get_num_threads()
        if threads == 1:
            return fn(*args, **kwargs)
        torch.set_num_threads(1)
        try:
            return fn(*args, **kwargs)
        finally:
            torch.set_num_threads(threads)

    return wrapper


def build_scene(task_class: type[ClothTask], task_config: Mapping[str, Any],
                solver: Mapping[str, Any] | None) -> dict:
    """The task's scene config with its overrides and the env's solver settings applied."""
    scene, _ = load_config(task_class.scene)
    scene = copy.deepcopy(scene)
    for table, values in task_class.scene_overrides(task_config).items():
        scene.setdefault(table, {}).update(values)
    settings = {**scene.get("solver", {}), **task_class.solver_defaults, **(solver or {})}
    tol = settings.pop("tolerance", DEFAULT_TOLERANCE)
    caps = ("max_iterations", "record_max_iterations")
    given = [v for k, v in (solver or {}).items() if k in caps]
    scene_caps = [settings.pop(k) for k in caps if k in settings]
    # The caller's cap wins; otherwise the env default, or a scene's larger one.
    cap = max(given) if given else max([DEFAULT_MAX_ITERATIONS, *scene_caps])
    settings.pop("record_tolerance", None)
    settings.update(tolerance=tol, record_tolerance=tol, max_iterations=cap, record_max_iterations=cap)
    scene["solver"] = settings
    return scene


def task_config(task_class: type[ClothTask], overrides: Mapping[str, Any]) -> dict:
    """The task's default config updated with ``overrides``; unknown keys are refused."""
    config = task_class.default_config()
    unknown = sorted(set(overrides) - set(config))
    if unknown:
        raise ParameterError(f"unknown argument(s) {unknown} for {task_class.__name__}; "
                             f"known: {sorted(config)}")
    config.update(overrides)
    return config


class CheckedAction(NamedTuple):
    """An action as ``check_action`` returns it: (N, action_dim) clipped, and the clipped
    entries per member (N,)."""

    action: np.ndarray
    clipped: np.ndarray


@dataclass
class StepResult:
    """One batched step, as numpy (the vector adapters convert and forward it). The infos are
    kept as columns, one array per key over the members (``columns``), plus the keys only some
    members have this step (``extras``: member -> {key: value}); ``info(i)`` is member i's
    info dict. Building N dicts and merging them back into arrays cost a 32-member napkin
    step as much Python time as everything else (serial time that caps the 2-thread gain)."""

    obs: np.ndarray
    reward: np.ndarray
    terminated: np.ndarray
    truncated: np.ndarray
    columns: dict[str, np.ndarray] = field(default_factory=dict)
    extras: dict[int, dict] = field(default_factory=dict)

    def info(self, i: int) -> dict:
        """Member ``i``'s info: every column's value as a Python scalar, then its extras."""
        info = {name: col[i].item() for name, col in self.columns.items()}
        info.update(self.extras.get(i, {}))
        return info

    @property
    def infos(self) -> list[dict]:
        return [self.info(i) for i in range(len(self.reward))]


class ClothEngine:
    """``num_envs`` members of ``task_class``; see the module docstring."""

    def __init__(self, task_class: type[ClothTask], num_envs: int = 1, solver: Mapping[str, Any] | None = None,
                 threads: int | None = None, **task_overrides: Any):
        self.task_config = task_config(task_class, task_overrides)
        self.scene = build_scene(task_class, self.task_config, solver)
        self.template = Simulator.from_config(self.scene)
        self.batch = _core.Batch(self.template._core, num_envs, threads)
        self.num_envs = num_envs
        self.task = task_class(self.scene, self.template.rest_positions, self.template.attachment_nodes,
                               self.task_config)
        self.action_low = np.full(self.task.action_dim, -self.task.action_bound)
        self.action_high = np.full(self.task.action_dim, self.task.action_bound)
        n, k = self.template.num_nodes, len(self.template.attachment_nodes)
        self._control = torch.zeros((num_envs, k, 3), dtype=torch.float64)
        self._steps = np.zeros(num_envs, dtype=np.int64)
        self._started = np.zeros(num_envs, dtype=bool)
        # Per episode: None until its first step, then "step" or "step_grad" (no mixing).
        self._mode: list[str | None] = [None] * num_envs
        # step_grad's graph: the state tensors after the last step (with history).
        self._x_t = torch.zeros((num_envs, n, 3), dtype=torch.float64)
        self._v_t = torch.zeros_like(self._x_t)
        self._episode = 0  # bumped at every reset, so a stale graph's backward is refused
        self._recording = False

    # -- episodes ------------------------------------------------------------------------------

    @single_threaded_torch
    def reset(self, indices: list[int], starts: list[Start]) -> np.ndarray:
        """Starts members ``indices`` at ``starts``; returns their observations (len, obs_dim)."""
        # A new episode starts a new graph: the control state of a step_grad episode is a
        # graph node and must not be written into.
        self._control = self._control.detach().clone()
        for i, s in zip(indices, starts):
            self.batch.reset(i, x=s.x, v=s.v)
            self._control[i] = torch.as_tensor(s.control, dtype=torch.float64).reshape(-1, 3)
            self._steps[i] = 0
            self._started[i] = True
            self._mode[i] = None
        x = torch.from_numpy(self.batch.positions())
        v = torch.from_numpy(self.batch.velocities())
        self._x_t, self._v_t = x, v
        self._episode += 1
        idx = torch.as_tensor(indices, dtype=torch.long)
        with torch.no_grad():
            return self.task.observe(x[idx], v[idx], self._control[idx]).numpy()

    def detach_graph(self) -> None:
        """Cuts the differentiable episode's graph here: later steps still differentiate, but no
        gradient flows back past this point (truncated backpropagation over windows)."""
        self._x_t, self._v_t, self._control = self._x_t.detach(), self._v_t.detach(), self._control.detach()

    def snapshot(self) -> dict[str, np.ndarray]:
        """Every member's state, control and episode step (for checkpoints; see ``restore``)."""
        return {"x": self.batch.positions(), "v": self.batch.velocities(),
                "control": self._control.detach().numpy().copy(), "steps": self._steps.copy()}

    @single_threaded_torch
    def restore(self, snapshot: Mapping[str, np.ndarray]) -> np.ndarray:
        """Puts every member back to a ``snapshot()`` (mid-episode included) for plain steps;
        returns the observations."""
        n = self.num_envs
        obs = self.reset(list(range(n)), [Start(x=snapshot["x"][i], v=snapshot["v"][i],
                                                control=snapshot["control"][i]) for i in range(n)])
        self._steps[:] = snapshot["steps"]
        return obs

    def _claim(self, mode: str) -> None:
        if not self._started.all():
            raise InputError("call reset() before stepping")
        for i, m in enumerate(self._mode):
            if m is not None and m != mode:
                other = "step_grad" if mode == "step" else "step"
                raise InputError(f"env {i} began this episode with {other}(); an episode is stepped "
                                 f"with step() or with step_grad(), not both: call reset() first")
        if self._recording != (mode == "step_grad"):
            self.batch.set_recording(mode == "step_grad")
            self._recording = mode == "step_grad"
        self._mode = [mode] * self.num_envs

    def check_action(self, action: Any) -> "CheckedAction":
        """The action as (N, action_dim) float64 clipped to the bounds, and how many entries
        per member were clipped. Wrong shape or non-finite values raise ``InputError``."""
        try:
            a = action.detach().cpu().numpy().astype(np.float64) if isinstance(action, torch.Tensor) \
                else np.asarray(action, dtype=np.float64)
        except (TypeError, ValueError) as e:
            raise InputError(f"action must be an array of numbers: {e}") from None
        expected = (self.num_envs, self.task.action_dim)
        if a.shape != expected and not (self.num_envs == 1 and a.shape == expected[1:]):
            raise InputError(f"action must have shape {expected[1:] if self.num_envs == 1 else expected}, "
                             f"got {a.shape}")
        a = a.reshape(expected)
        if not np.isfinite(a).all():
            raise InputError("action contains NaN or inf")
        clipped = np.clip(a, self.action_low, self.action_high)
        return CheckedAction(clipped, (clipped != a).sum(axis=1))

    # -- steps -----------------------------------------------------------------------------------

    @single_threaded_torch
    def step(self, action: Any) -> StepResult:
        """One step of every member (numpy in, numpy out, no graph). ``action`` may also be
        what ``check_action`` returned for it (checked once, clip counts kept)."""
        if isinstance(action, CheckedAction):
            a, clipped = action
        else:
            a, clipped = self.check_action(action)
        self._claim("step")
        with torch.no_grad():
            control, drive = self.task.drive(self._control, torch.from_numpy(a))
            errors = self.batch.step(attachment_targets=_np(drive.targets), external_forces=_np(drive.forces))
            x = torch.from_numpy(self.batch.positions())
            v = torch.from_numpy(self.batch.velocities())
            failed = np.array([e is not None for e in errors])
            # A failed member stays at its previous state and control (the core rolled it back).
            self._control = torch.where(torch.as_tensor(failed)[:, None, None], self._control, control) \
                if failed.any() else control
            self._steps += ~failed
            obs, reward, terms = self._score(x, v)
            return self._result(obs, reward, terms, x, v, errors, clipped)

    @single_threaded_torch
    def step_grad(self, action: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, StepResult]:
        """One differentiable step of every member: ``action`` (N, action_dim) float64 torch
        (may require grad). Returns the observation (N, obs_dim) and reward (N,) as tensors
        whose graph runs through the Rust adjoint, and the numpy result for the rest."""
        if not isinstance(action, torch.Tensor) or action.dtype != torch.float64:
            raise InputError("step_grad takes a float64 torch tensor action")
        _, clipped = self.check_action(action)
        if len(set(self._steps.tolist())) != 1:
            raise InputError("step_grad steps every member together: reset all of them at once "
                             "(their episodes are at different steps)")
        self._claim("step_grad")
        a = action.reshape(self.num_envs, self.task.action_dim)
        low, high = (torch.as_tensor(b, dtype=torch.float64) for b in (self.action_low, self.action_high))
        control, drive = self.task.drive(self._control, torch.clamp(a, low, high))
        x, v = _BatchStep.apply(self, drive.targets, drive.forces, self._x_t, self._v_t)
        self._control, self._x_t, self._v_t = control, x, v
        self._steps += 1
        obs, reward, terms = self._score(x, v)
        errors = [None] * self.num_envs
        return obs, reward, self._result(obs.detach(), reward.detach(), terms, x.detach(), v.detach(), errors,
                                         clipped)

    def _score(self, x: torch.Tensor, v: torch.Tensor):
        """Observation, reward and loss terms of the members' states (members grouped by
        their step index, which the task's per-step loss may depend on)."""
        obs = self.task.observe(x, v, self._control)
        steps = np.unique(self._steps)
        if len(steps) == 1:
            # The usual case (members in step): one group, no reordering.
            terms = self.task.loss_terms(x, v, self._control, int(steps[0]))
            return obs, -sum(terms.values()), terms
        parts: dict[str, list] = {}
        order = []
        for step in steps:
            idx = torch.as_tensor(np.flatnonzero(self._steps == step))
            order.append(idx)
            for name, t in self.task.loss_terms(x[idx], v[idx], self._control[idx], int(step)).items():
                parts.setdefault(name, []).append(t)
        inverse = torch.argsort(torch.cat(order))
        terms = {name: torch.cat(ts)[inverse] for name, ts in parts.items()}
        reward = -sum(terms.values())
        return obs, reward, terms

    def _result(self, obs, reward, terms, x, v, errors, clipped) -> StepResult:
        failed = np.array([e is not None for e in errors])
        truncated = (self._steps >= self.task.horizon) | failed
        stats = self.batch.last_stats()
        columns = {name: t.detach().numpy().astype(np.float64) for name, t in terms.items()}
        columns.update(step=self._steps.copy(), solver_iterations=stats["iterations"],
                       solver_converged=stats["converged"], action_clipped=np.asarray(clipped, dtype=np.int64))
        extras: dict[int, dict] = {}
        for i in np.flatnonzero(failed):
            extras[int(i)] = {"solver_error": f"{type(errors[i]).__name__}: {errors[i]}"}
        if truncated.any():
            with torch.no_grad():
                success = self.task.success(x, v, self._control.detach())
            for i in np.flatnonzero(truncated):
                extras.setdefault(int(i), {})["success"] = bool(success[i]) and not failed[i]
        return StepResult(obs=obs.numpy().copy(), reward=reward.numpy().copy(),
                          terminated=np.zeros(self.num_envs, dtype=bool), truncated=truncated,
                          columns=columns, extras=extras)


def _np(t: torch.Tensor | None) -> np.ndarray | None:
    return None if t is None else t.detach().cpu().numpy().astype(np.float64)


class _BatchStep(torch.autograd.Function):
    """One recorded batched step as an autograd node: its backward is the one-step adjoint of
    the recorded step (no second forward). Inputs: engine, targets (N, k, 3) or None, forces
    (N, n, 3) or None, x_prev, v_prev (N, n, 3); outputs x, v (N, n, 3)."""

    @staticmethod
    def forward(ctx, engine, targets, forces, x_prev, v_prev):
        k = int(engine._steps[0])
        errors = engine.batch.step(attachment_targets=_np(targets), external_forces=_np(forces))
        failed = [(i, e) for i, e in enumerate(errors) if e is not None]
        if failed:
            i, e = failed[0]
            raise type(e)(f"env {i}, step {k}: {e} (a differentiable episode cannot continue past a "
                          f"failed step; call reset())")
        ctx.engine, ctx.k, ctx.episode = engine, k, engine._episode
        ctx.has_targets, ctx.has_forces = targets is not None, forces is not None
        return torch.from_numpy(engine.batch.positions()), torch.from_numpy(engine.batch.velocities())

    @staticmethod
    @single_threaded_torch
    def backward(ctx, gx, gv):
        engine = ctx.engine
        if engine._episode != ctx.episode:
            raise InputError("this step's episode was reset before backward(): its recording is gone; "
                             "call backward() before reset()")
        g = engine.batch.backward_step(ctx.k, _np(gx), _np(gv))
        for i, warnings_i in enumerate(g["warnings"]):
            for w in warnings_i:
                import warnings

                warnings.warn(f"diffcloth gradient (env {i}, step {ctx.k}): {w}", stacklevel=2)
        t = lambda a: torch.from_numpy(a)  # noqa: E731
        return (None, t(g["attachment_targets"]) if ctx.has_targets else None,
                t(g["external_forces"]) if ctx.has_forces else None, t(g["x"]), t(g["v"]))
