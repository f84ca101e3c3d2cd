"""Generic metrics of the stability suite: a :class:`Monitor` observes every step of a rollout
(penetration, thickness layer, self distance, energy, non-finite values, backward statistics);
the bounds the tests hold them to are the constants below (see the package docstring)."""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np

from diffcloth_gym import Simulator

#: A node may be this far inside an obstacle's surface (beyond the whole thickness layer), m.
PENETRATION_SLACK_M = 1e-6
#: A node may intrude this fraction of ``contact.thickness`` into the thickness layer.
LAYER_FRACTION = 0.1
#: A non-adjacent node pair may be this fraction of ``self_collision.radius`` closer than it.
SELF_FRACTION = 0.01
#: Unforced cases: ``E(t) / E(0)`` may exceed 1 by this much (round-off, solver tolerance).
ENERGY_BOUND = 1.0 + 1e-6
#: A rollout whose energy ratio passes this has blown up: it is stopped (its energy check
#: has failed already) so that the blow-up does not cost minutes.
BLOWUP_RATIO = 1e3
#: The gradient entries of ``backward()`` (solver statistics and the profile are not gradients).
GRADIENT_KEYS = ("x0", "v0", "attachment_targets", "external_forces", "external_forces_constant",
                 "k_stretch", "k_bend", "k_attach", "density", "wind_omega", "wind_phi", "mu_self",
                 "mu_obstacles", "gravity", "wind_direction")


def count_nonfinite(a: Any) -> int:
    """Number of non-finite entries in a (possibly nested) gradient value."""
    if a is None or isinstance(a, (str, bool)):
        return 0
    if isinstance(a, dict):
        return sum(count_nonfinite(v) for v in a.values())
    if isinstance(a, (list, tuple)):
        return sum(count_nonfinite(v) for v in a)
    arr = np.asarray(a)
    if arr.dtype.kind not in "fc":
        return 0
    return int(arr.size - np.count_nonzero(np.isfinite(arr)))


def adjacency(sim: Simulator) -> np.ndarray:
    """(n, n) booleans: node pairs that share a triangle, and the diagonal. The simulator never
    makes these a self-contact pair (``collision/self_collision.rs``)."""
    n = sim.num_nodes
    adj = np.eye(n, dtype=bool)
    tri = sim.triangles
    for a in range(3):
        for b in range(3):
            adj[tri[:, a], tri[:, b]] = True
    return adj


def min_pair_distance(x: np.ndarray, excluded: np.ndarray, chunk: int = 512) -> float:
    """Smallest distance between two nodes not marked in the boolean ``excluded`` (n, n)."""
    sq = np.einsum("ij,ij->i", x, x)
    best = math.inf
    for start in range(0, len(x), chunk):
        block = x[start:start + chunk]
        # |a-b|^2 = |a|^2 + |b|^2 - 2 a.b is only used to find each block's closest pair; that
        # pair's distance is then computed exactly.
        d2 = sq[start:start + chunk, None] + sq[None, :] - 2.0 * block @ x.T
        d2[excluded[start:start + chunk]] = np.inf
        i, j = np.unravel_index(np.argmin(d2), d2.shape)
        if np.isfinite(d2[i, j]):
            best = min(best, float(np.linalg.norm(x[start + i] - x[j])))
    return best


class BlowUp(Exception):
    """Raised by :meth:`Monitor.observe` when the energy ratio passes :data:`BLOWUP_RATIO`."""


class Monitor:
    """Collects the generic metrics of one or more rollouts, one :meth:`observe` per step.

    Several simulators may feed one monitor (the placements of a garment case): call
    :meth:`start` with each before its first step. ``energy``: track the energy ratio (only
    meaningful for unforced rollouts).
    """

    def __init__(self, energy: bool):
        self.energy = energy
        self.steps = 0
        self.nan_count = 0
        self.diverged: str | None = None
        self.blew_up: str | None = None
        self.max_penetration = -math.inf
        self.max_layer_intrusion = -math.inf
        self.thickness: float | None = None
        self.min_self_distance = math.inf
        self.self_radius: float | None = None
        self.max_energy_ratio: float | None = None
        self.max_stretch = -math.inf
        self.min_stretch = math.inf
        self.unconverged = 0
        self.convergence_warnings = 0  # ConvergenceWarning raised by step()
        self.obstacle_contacts = 0  # active (stick or slip) contacts, summed over steps
        self.self_contacts = 0
        self.max_self_contacts = 0  # the most active self-contacts in one step
        self.max_contacts = 0
        self.backward_steps = 0
        self.fallbacks = 0
        self.grad_warnings: list[str] = []
        self.backward_errors: list[str] = []
        self.started = time.perf_counter()
        self._run: dict | None = None

    def start(self, sim: Simulator) -> None:
        """Begins observing a rollout of ``sim`` from its current state."""
        self._finish_energy()
        cfg = sim.config
        effects = set(cfg["effects"])
        obstacles = len(cfg.get("obstacles", [])) if "obstacle_contact" in effects else 0
        if obstacles:
            self.thickness = float(cfg.get("contact", {}).get("thickness", 0.01))
        adj = None
        if "self_collision" in effects:
            self.self_radius = float(cfg["self_collision"]["radius"])
            adj = adjacency(sim)
        g = np.asarray(sim.params()["gravity"], dtype=float)
        gmag = float(np.linalg.norm(g))
        up = -g / gmag if gmag > 0 else np.array([0.0, 1.0, 0.0])
        self._run = {"sim": sim, "obstacles": obstacles, "adjacency": adj, "up": up, "gmag": gmag,
                     "mass": float(sim.masses.sum()), "energies": [], "min_height": math.inf}
        self._observe_state(contacts=False)

    def observe(self) -> None:
        """Records the state after a step (call once per step)."""
        if self._run is None:
            raise RuntimeError("call Monitor.start(sim) before observe()")
        self.steps += 1
        self.unconverged += not self._run["sim"].last_step()["converged"]
        self._observe_state(contacts=True)

    def _observe_state(self, contacts: bool) -> None:
        run = self._run
        sim = run["sim"]
        x, v = sim.positions, sim.velocities
        bad = x.size - np.count_nonzero(np.isfinite(x)) + v.size - np.count_nonzero(np.isfinite(v))
        self.nan_count += int(bad)
        if bad:
            return
        for i in range(run["obstacles"]):
            d = float(sim.obstacle_distance(i).min())
            self.max_penetration = max(self.max_penetration, -d)
            self.max_layer_intrusion = max(self.max_layer_intrusion, self.thickness - d)
        if run["adjacency"] is not None:
            self.min_self_distance = min(self.min_self_distance, min_pair_distance(x, run["adjacency"]))
        s = sim.principal_stretches()
        self.max_stretch = max(self.max_stretch, float(s.max()))
        self.min_stretch = min(self.min_stretch, float(s.min()))
        if contacts:
            c = sim.contacts()
            active = c["branch"] != 0
            on_self = int(np.count_nonzero(active & (c["obstacle"] < 0)))
            self.obstacle_contacts += int(np.count_nonzero(active)) - on_self
            self.self_contacts += on_self
            self.max_self_contacts = max(self.max_self_contacts, on_self)
            self.max_contacts = max(self.max_contacts, int(np.count_nonzero(active)))
        if self.energy:
            run["energies"].append(sim.mechanical_energy())
            run["min_height"] = min(run["min_height"], float((x @ run["up"]).min()))
            e0, e = (np.array([run["energies"][0], run["energies"][-1]])
                     - run["mass"] * run["gmag"] * run["min_height"])
            if e0 > 0 and e > BLOWUP_RATIO * e0:
                raise BlowUp(f"energy ratio {e / e0:.3g} after {self.steps} steps")

    def _finish_energy(self) -> None:
        run = self._run
        if run is None or not self.energy or not run["energies"]:
            return
        # Potential measured from the lowest height reached: E >= 0 along the run.
        e = np.asarray(run["energies"]) - run["mass"] * run["gmag"] * run["min_height"]
        if e[0] > 0:
            ratio = float(np.max(e) / e[0])
        else:  # started at rest at the lowest height of its run: any energy gain is unbounded
            ratio = 1.0 if np.max(e) <= e[0] else math.inf
        self.max_energy_ratio = ratio if self.max_energy_ratio is None else max(self.max_energy_ratio, ratio)
        run["energies"] = []

    def gradients(self, g: dict) -> None:
        """Records one ``backward()`` result."""
        self.nan_count += sum(count_nonfinite(g[k]) for k in GRADIENT_KEYS)
        self.backward_steps += len(g["fell_back"])
        self.fallbacks += int(sum(g["fell_back"]))
        self.grad_warnings += list(g["warnings"])

    def metrics(self) -> dict:
        """The generic metrics as a flat dict (see the module docstring)."""
        self._finish_energy()

        def finite(v: float) -> float | None:
            return None if math.isinf(v) else v

        return {
            "steps": self.steps,
            "thickness_m": self.thickness,
            "max_penetration_m": finite(self.max_penetration),
            "max_layer_intrusion_m": finite(self.max_layer_intrusion),
            "self_radius_m": self.self_radius,
            "min_self_distance_m": finite(self.min_self_distance),
            "max_energy_ratio": self.max_energy_ratio,
            "max_stretch": finite(self.max_stretch),
            "min_stretch": finite(self.min_stretch),
            "unconverged_steps": self.unconverged,
            "convergence_warnings": self.convergence_warnings,
            "obstacle_contacts": self.obstacle_contacts,
            "self_contacts": self.self_contacts,
            "max_self_contacts": self.max_self_contacts,
            "max_contacts": self.max_contacts,
            "backward_steps": self.backward_steps,
            "fallbacks": self.fallbacks,
            "nan_count": self.nan_count,
            "diverged": self.diverged,
            "blew_up": self.blew_up,
            "backward_errors": len(self.backward_errors),
            "backward_error_texts": sorted(set(self.backward_errors)),
            "grad_warnings": len(self.grad_warnings),
            "grad_warning_texts": sorted(set(self.grad_warnings)),
            "wall_s": time.perf_counter() - self.started,
        }
