"""Python face of the Rust simulator: config loading and array conversion, nothing else."""

from __future__ import annotations

import json
import os
import warnings
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from diffcloth_gym import _core
from diffcloth_gym.errors import ConfigError, ConvergenceWarning, InputError, PenetrationWarning
from diffcloth_gym.scenes import load_config


def _nodes(name: str, value: Any, rows: int | None = None) -> np.ndarray:
    """Converts array-likes to a contiguous (n, 3) float64 array, naming ``name`` in errors."""
    try:
        a = np.ascontiguousarray(value, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise InputError(f"{name} must be an (n, 3) array of numbers: {e}") from None
    if a.ndim != 2 or a.shape[1] != 3:
        raise InputError(f"{name} must have shape (n, 3), got {a.shape}")
    if rows is not None and a.shape[0] != rows:
        raise InputError(f"{name} must have {rows} rows, got {a.shape[0]}")
    return a


def _real(name: str, value: Any) -> float:
    """A real-number argument as a float; anything else (a string, None, an int too large for a
    float) is an InputError naming ``name``, not Python's TypeError/ValueError/OverflowError."""
    if not isinstance(value, (str, bytes)):
        try:
            return float(value)
        except (TypeError, ValueError, OverflowError):
            pass
    raise InputError(f"{name} must be a real number, got {value!r}")


class Simulator:
    """A cloth scene simulated forward in time (projective dynamics, implicit Euler).

    Build one with :meth:`from_config`. Arrays are numpy float64, one row per node (x, y, z).
    Long calls run in Rust with the GIL released. Bad input raises a ``ValueError``
    subclass (see :mod:`diffcloth_gym.errors`) and leaves the simulator usable.
    """

    def __init__(self, core: _core.Simulator, config: dict):
        self._core = core
        #: The scene config this simulator was built from (a dict).
        self.config = config
        # Bumped by everything that changes the tape (reset, step, set_recording), so a
        # holder of a recorded rollout (diffcloth_gym.torch) can tell it is still the same.
        self._tape_version = 0
        self._warn_overlaps(stacklevel=4)

    @classmethod
    def from_config(cls, config: str | Path | Mapping[str, Any]) -> "Simulator":
        """Builds a simulator from a shipped scene name (see
        :func:`diffcloth_gym.scenes.scene_names`), a TOML path, or a dict."""
        cfg, base = load_config(config)
        try:
            text = json.dumps(cfg)
        except (TypeError, ValueError) as e:
            raise ConfigError(f"config is not serializable: {e}") from None
        except RecursionError:
            raise ConfigError("config is nested too deeply (or contains itself)") from None
        return cls(_core.Simulator.from_json(text, str(base)), cfg)

    # -- state ---------------------------------------------------------------------------
    def reset(self, x: Any = None, v: Any = None) -> None:
        """Sets positions ``x`` (default: rest shape) and velocities ``v`` (default: zero),
        time to 0 and attachment targets to the attached nodes' positions. Positions inside an
        obstacle, or self-contact pairs closer than the radius, raise a
        :class:`~diffcloth_gym.errors.PenetrationWarning` (with the depth): the first step
        throws them out."""
        n = self.num_nodes
        self._tape_version += 1
        self._core.reset(None if x is None else _nodes("x", x, n), None if v is None else _nodes("v", v, n))
        self._warn_overlaps(stacklevel=3)

    def _warn_overlaps(self, stacklevel: int) -> None:
        """A :class:`PenetrationWarning` if the state starts inside an obstacle or with
        self-contact pairs closer than the radius: the first step would throw them out."""
        message = self._core.overlap_warning()
        if message:
            warnings.warn(message, PenetrationWarning, stacklevel=stacklevel)

    def step(self, attachment_targets: Any = None, external_forces: Any = None, steps: int = 1) -> dict:
        """Advances ``steps`` implicit-Euler steps (default 1).

        ``attachment_targets``: (k, 3) targets of the k attached nodes (the end effectors);
        ``None`` keeps the previous targets. ``external_forces``: (n, 3) forces in N per node
        (needs the ``external_forces`` effect). Returns the last step's solver stats
        ``{"iterations", "residual", "converged", "contacts": {"take_off", "stick", "slip"}}``.
        """
        if not isinstance(steps, int) or steps < 1:
            raise InputError(f"steps must be a positive integer, got {steps!r}")
        k = len(self.attachment_nodes)
        targets = None if attachment_targets is None else _nodes("attachment_targets", attachment_targets, k)
        forces = None if external_forces is None else _nodes("external_forces", external_forces, self.num_nodes)
        self._tape_version += 1
        before = self._core.profile()["unconverged_steps"]
        stats = self._core.step(targets, forces, steps)
        missed = self._core.profile()["unconverged_steps"] - before
        if missed and self._core.solver()["tolerance"] > 0:
            hint = ""
            active = stats["contacts"]["stick"] + stats["contacts"]["slip"]
            if active and (self.config.get("contact") or {}).get("response", "auto") != "delassus":
                hint = ("; with stiff cloth at large steps, contact.response = 'delassus' keeps every iterate "
                        "out of the obstacles ('auto', the default, switches to it only on steps that stall "
                        "with few, stiff contacts)")
            warnings.warn(f"{int(missed)} step(s) stopped at the iteration cap above the tolerance (last: residual "
                          f"{stats['residual']:.1e} after {stats['iterations']} iterations){hint}",
                          ConvergenceWarning, stacklevel=2)
        return stats

    @property
    def positions(self) -> np.ndarray:
        """Node positions, (n, 3) float64 (a copy)."""
        return self._core.positions

    @property
    def velocities(self) -> np.ndarray:
        """Node velocities, (n, 3) float64 (a copy)."""
        return self._core.velocities

    @property
    def rest_positions(self) -> np.ndarray:
        """Rest shape (after the config's placement), (n, 3)."""
        return self._core.rest_positions

    @property
    def triangles(self) -> np.ndarray:
        """Triangle node indices, (t, 3) int64."""
        return self._core.triangles

    @property
    def masses(self) -> np.ndarray:
        """Lumped node masses in kg, (n,)."""
        return np.asarray(self._core.masses)

    @property
    def num_nodes(self) -> int:
        return self._core.num_nodes

    @property
    def time(self) -> float:
        """Simulated time since reset in seconds (settable: wind and moving obstacles use it)."""
        return self._core.time

    @time.setter
    def time(self, t: float) -> None:
        self._core.time = _real("time", t)

    @property
    def attachment_nodes(self) -> list[int]:
        """Indices of the attached nodes, in the order of ``attachment_targets``."""
        return self._core.attachment_nodes

    @property
    def attachment_targets(self) -> np.ndarray:
        """Current attachment targets, (k, 3)."""
        return self._core.attachment_targets

    @property
    def handles(self) -> list[int]:
        """Suggested end-effector nodes of a garment mesh (empty for grids and OBJ meshes)."""
        return self._core.handles

    @property
    def effects(self) -> list[str]:
        """The effects this scene simulates."""
        return self._core.effects

    # -- parameters ----------------------------------------------------------------------
    #: Every differentiable parameter's name: the keys of :meth:`params`, :meth:`set_params`,
    #: the gradient dict of :meth:`backward` and ``diffcloth_gym.torch`` (one registry).
    PARAM_NAMES: tuple[str, ...] = tuple(_core.PARAM_NAMES)

    def params(self) -> dict:
        """Physical parameters by name: h, density, k_stretch, k_bend, k_attach, gravity,
        wind_direction, wind_omega, wind_phi, mu_obstacles (one friction coefficient per
        obstacle, config order) and mu_self (scenes with self-collision)."""
        return self._core.params()

    def set_params(self, **params: Any) -> None:
        """Changes physical parameters by the names of :meth:`params` (e.g.
        ``set_params(k_stretch=800.0, mu_obstacles=[0.3])``); refactors the system matrix only
        when h, density or a stiffness changes. Unknown names or invalid values raise
        :class:`~diffcloth_gym.errors.ParameterError` and change nothing."""
        self._core.set_params(**{k: np.asarray(v, dtype=np.float64).tolist() if isinstance(v, np.ndarray) else v
                                 for k, v in params.items()})

    def solver(self) -> dict:
        """Accuracy knobs of every step, recorded or not: max_iterations, tolerance,
        acceleration, history, parallel, polish."""
        return self._core.solver()

    def set_solver(self, **settings: Any) -> None:
        """Changes solver settings by name (see :meth:`solver`). ``preset="simulation"``
        (tolerance 1e-8, cap 300: the default) or ``preset="gradient"`` (1e-11, cap 10000: what
        the adjoint needs; 1.1-1.7x the cost of a loss with its gradient) sets tolerance and
        cap, explicit settings override it. A recorded rollout is the same trajectory as an
        unrecorded one with the same settings."""
        self._core.set_solver(**settings)

    # -- gradients -----------------------------------------------------------------------
    def set_recording(self, on: bool = True, checkpoint_every: int | None = None) -> None:
        """Starts recording steps on a tape for :meth:`backward` (clearing any previous tape),
        or stops. :meth:`reset` also clears the tape. With ``checkpoint_every=K`` only every
        K-th state and each step's inputs are kept (memory no longer grows with the mesh size
        times the horizon); :meth:`backward` re-simulates one segment at a time and returns the
        same gradients."""
        self._tape_version += 1
        self._core.set_recording(bool(on), checkpoint_every)

    def tape_info(self) -> tuple[int, int]:
        """``(recorded steps, bytes held by the tape)``."""
        return self._core.tape_info()

    def backward(self, dl_dx: Any = None, dl_dv: Any = None, solver: str | None = None,
                 tolerance: float | None = None, max_iterations: int | None = None) -> dict:
        """Adjoint gradients of a loss through the recorded steps.

        ``dl_dx`` and ``dl_dv``: gradients of the loss with respect to the positions and
        velocities after the recorded steps, each one of: ``None`` (zero); an (N, n, 3) array
        (one entry per recorded step); an (n, 3) array (the final step only: a terminal loss);
        or a dict ``{step: (n, 3) array}`` (negative steps count from the end, so ``{-1: g}``
        is the final step). ``solver``: ``"krylov"`` (CG, or BiCGStab with active contacts,
        preconditioned by the PD factorization, or, once that takes over 50 iterations in a
        pass, by each step's own sparse-Cholesky-factored Hessian; default), ``"direct"``
        (sparse LU) or
        ``"fixed_point"`` (the paper's Eqn. 30); iterative solves that stall fall back to
        ``"direct"`` and are counted in ``fell_back``.

        Returns numpy arrays ``x0``, ``v0`` (n, 3); per step ``attachment_targets`` (N, k, 3)
        and ``external_forces`` (N, n, 3; (N, 0, 3) without the effect), and
        ``external_forces_constant`` (n, 3), the gradient for a force held constant over the
        rollout (None without the effect); every parameter of :attr:`PARAM_NAMES` by the name
        :meth:`params` and :meth:`set_params` use (scalars; 3-lists ``gravity``,
        ``wind_direction``; ``mu_obstacles`` one per obstacle); per-step solver stats arrays
        ``iterations``, ``fell_back``, ``factored`` (preconditioned by the step's factored
        Hessian), ``residual``; a stage ``profile``; and ``warnings``: the
        reasons the gradient may be untrustworthy (e.g. recorded steps that stopped above the
        residual the adjoint needs: record with ``set_solver(preset="gradient")``). Gradients
        are never clipped or rescaled.
        """
        steps, _ = self.tape_info()
        n = self.num_nodes

        def grads(name, a):
            if a is None:
                return None
            if isinstance(a, Mapping):
                out = np.zeros((steps, n, 3))
                for k, g in a.items():
                    if not isinstance(k, (int, np.integer)) or not -steps <= k < steps:
                        raise InputError(f"{name} has step {k!r}; the tape has {steps} recorded steps")
                    out[k] = _nodes(f"{name}[{k}]", g, n)
                return out
            try:
                arr = np.ascontiguousarray(a, dtype=np.float64)
            except (TypeError, ValueError) as e:
                raise InputError(f"{name} must be an (N, n, 3) or (n, 3) array or a dict: {e}") from None
            if arr.shape == (n, 3) and steps:
                # A terminal loss: the final step only.
                out = np.zeros((steps, n, 3))
                out[-1] = arr
                return out
            if arr.shape != (steps, n, 3):
                raise InputError(f"{name} must have shape ({steps}, {n}, 3) or ({n}, 3), got {arr.shape}")
            return arr
        out = self._core.backward(grads("dl_dx", dl_dx), grads("dl_dv", dl_dv), solver,
                                  None if tolerance is None else _real("tolerance", tolerance),
                                  max_iterations)
        forces = out["external_forces"]
        out["external_forces_constant"] = forces.sum(axis=0) if forces.size else None
        return out

    def set_obstacle_mu(self, index: int, mu: float) -> None:
        """Sets the Coulomb friction coefficient of obstacle ``index``."""
        # The binding checks both and names the one that is wrong (int() and float() here
        # raised TypeError/ValueError, and int(1.5) silently picked obstacle 1).
        self._core.set_obstacle_mu(index, mu)

    def set_self_mu(self, mu: float) -> None:
        """Sets the self-contact friction coefficient."""
        self._core.set_self_mu(mu)

    # -- diagnostics ---------------------------------------------------------------------
    def profile(self) -> dict:
        """Wall time per stage in seconds (``local_s``, ``global_s``, ``detection_s``,
        ``contact_s``, ``other_s``, ``refactor_s``, ``total_s``) and counters (``steps``,
        ``iterations``, ``contacts_take_off``/``_stick``/``_slip`` summed over steps, ...) since
        the last :meth:`reset_profile`."""
        return self._core.profile()

    def reset_profile(self) -> None:
        self._core.reset_profile()

    def last_step(self) -> dict:
        """Solver stats of the last step."""
        return self._core.last_step()

    def contacts(self) -> dict:
        """The last step's contacts as arrays (one entry per contact): ``node_a``, ``node_b``
        (-1 for obstacle contacts), ``obstacle`` (-1 for self-contacts), ``normal`` (k, 3),
        ``gap``, ``mu``, ``branch`` (0 take off, 1 stick, 2 slip), ``impulse`` (k, 3) in N s
        acting on ``node_a`` (its opposite acts on ``node_b``)."""
        return self._core.contacts()

    def obstacle_distance(self, index: int = 0) -> np.ndarray:
        """Signed distance of every node to obstacle ``index`` (positive outside), (n,)."""
        return np.asarray(self._core.obstacle_distance(index))

    def set_trace(self, on: bool = True) -> None:
        """Records each step's PD convergence trace (see :meth:`trace`)."""
        self._core.set_trace(bool(on))

    def trace(self) -> np.ndarray:
        """The last step's convergence trace, (iterations, 2): the step objective E (without
        contact) and the RMS PD update |G(x) - x| in metres after each iteration."""
        return np.asarray(self._core.trace())

    def mechanical_energy(self) -> float:
        """Kinetic + gravitational + elastic energy of the current state (J)."""
        return self._core.mechanical_energy()

    def principal_stretches(self) -> np.ndarray:
        """Principal stretches (s1 >= s2) of each triangle, (t, 2)."""
        return self._core.principal_stretches()

    def write_obj(self, path: str | Path) -> None:
        """Writes the current state as a Wavefront OBJ file."""
        # str(None) would be the file name "None": only real paths are accepted.
        if not isinstance(path, (str, os.PathLike)) or not os.fspath(path):
            raise InputError(f"path must be a file path (str or os.PathLike), got {path!r}")
        self._core.write_obj(os.fspath(path))

    # -- rendering -----------------------------------------------------------------------
    def render(self, width: int = 480, height: int = 480, camera: Mapping[str, Any] | None = None) -> np.ndarray:
        """The current state as a (height, width, 3) uint8 RGB frame, drawn by the Rust software
        renderer (no OpenGL; see :mod:`diffcloth_gym.rendering` for the camera dict)."""
        from diffcloth_gym.rendering import render_rgb

        return render_rgb(self, width, height, camera)
