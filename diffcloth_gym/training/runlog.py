"""Run folders: CSV logs, atomic checkpoints and the RNG states a resumed run needs.

A run folder holds ``checkpoint.pt`` (the latest; written to a temporary file and renamed, so
a run killed while saving keeps the previous one), ``train.csv`` and ``eval.csv``. On resume
the CSV rows after the checkpoint are dropped (they belong to work that is redone)."""

from __future__ import annotations

import csv
import hashlib
import json
import os
import random
import warnings
import weakref
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import torch


class CsvLog:
    """Appends dict rows to a CSV file; the header is the first row's keys (later rows may
    not add keys). ``truncate(key, last)`` keeps only rows with ``row[key] <= last``."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.fields: list[str] | None = None
        if self.path.exists():
            with self.path.open() as f:
                self.fields = next(csv.reader(f), None)

    def write(self, row: Mapping[str, Any]) -> None:
        new = self.fields is None
        if new:
            self.fields = list(row)
        with self.path.open("a", newline="") as f:
            w = csv.DictWriter(f, fieldnames=self.fields)
            if new:
                w.writeheader()
            w.writerow({k: _fmt(row.get(k, "")) for k in self.fields})

    def rows(self) -> list[dict[str, str]]:
        if not self.path.exists():
            return []
        with self.path.open() as f:
            return list(csv.DictReader(f))

    def truncate(self, key: str, last: float) -> None:
        rows = [r for r in self.rows() if float(r[key]) <= last]
        if self.fields is None:
            return
        with self.path.open("w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=self.fields)
            w.writeheader()
            w.writerows(rows)


def _fmt(v: Any) -> Any:
    return repr(v) if isinstance(v, float) else v


def save_atomic(obj: Any, path: str | Path) -> None:
    path = Path(path)
    tmp = path.with_suffix(path.suffix + ".tmp")
    torch.save(obj, tmp)
    os.replace(tmp, path)


def load_checkpoint(path: str | Path) -> dict | None:
    path = Path(path)
    if not path.exists():
        return None
    # Our own files: they hold numpy generators and dicts besides tensors.
    return torch.load(path, weights_only=False)


def rng_states() -> dict[str, Any]:
    """The global RNG states (torch, numpy, random) that training may draw from."""
    return {"torch": torch.get_rng_state(), "numpy": np.random.get_state(), "random": random.getstate()}


def set_rng_states(states: Mapping[str, Any]) -> None:
    torch.set_rng_state(states["torch"])
    np.random.set_state(states["numpy"])
    random.setstate(states["random"])


def physics_fingerprint(engine: Any) -> dict[str, Any]:
    """What a run's simulated steps depend on besides its own config: the env's solver settings,
    a hash of its physics (mesh, masses, parameters, effects, obstacles, contact response) and
    ``dynamics``, a hash of a short seeded episode (:func:`dynamics_probe`), which also changes
    with the simulator's code or the task's loss. Paths are left out, so a checkout elsewhere
    resumes the same run. Computed once per engine."""
    cached = _FINGERPRINTS.get(engine)
    if cached is not None:
        return cached
    sim, scene = engine.template, engine.scene
    h = hashlib.sha1()
    for a in (sim.rest_positions, sim.masses, sim.triangles):
        h.update(np.ascontiguousarray(a).tobytes())
    h.update(json.dumps({"params": sim.params(), "effects": sim.effects, "handles": sim.attachment_nodes,
                         **{k: scene.get(k) for k in ("obstacles", "contact", "self_collision")}},
                        sort_keys=True, default=str).encode())
    fingerprint = {"solver": sim.solver(), "physics": h.hexdigest(), "dynamics": dynamics_probe(engine)}
    _FINGERPRINTS[engine] = fingerprint
    return fingerprint


_FINGERPRINTS: "weakref.WeakKeyDictionary[Any, dict[str, Any]]" = weakref.WeakKeyDictionary()

#: Steps of :func:`dynamics_probe`'s episode.
PROBE_STEPS = 20


def dynamics_probe(engine: Any, steps: int = PROBE_STEPS) -> str:
    """SHA-1 of the states and loss terms of one episode from the task's ``probe_start`` under
    seeded random actions, simulated apart from the engine with its scene and solver
    settings, and of the gradient of a seeded linear loss on its states (the adjoint: what
    APG and SHAC learn from). Settings and physics hashes cannot see a new build whose solver
    takes another path to the same tolerance (session 11's contact sweeps): its trajectories
    and gradients differ at the tolerance's level, so a run resumed on it would mix two
    simulators."""
    from diffcloth_gym.simulator import Simulator

    task = engine.task
    rng = np.random.default_rng(0)
    start = task.probe_start()
    sim = Simulator.from_config(engine.scene)
    sim.reset(x=start.x, v=start.v)
    sim.set_recording(True)
    control = torch.as_tensor(start.control, dtype=torch.float64).reshape(1, -1, 3)
    h = hashlib.sha1()
    # Steps stopped at the iteration cap (and what the adjoint says of them) are part of what
    # the hash sees, not news to the user.
    with torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for step in range(1, steps + 1):
            action = torch.from_numpy(rng.uniform(-task.action_bound, task.action_bound, (1, task.action_dim)))
            control, drive = task.drive(control, action)
            sim.step(attachment_targets=None if drive.targets is None else drive.targets[0].numpy(),
                     external_forces=None if drive.forces is None else drive.forces[0].numpy())
            x, v = torch.from_numpy(sim.positions)[None], torch.from_numpy(sim.velocities)[None]
            h.update(x.numpy().tobytes() + v.numpy().tobytes())
            for term in task.loss_terms(x, v, control, step).values():
                h.update(term.numpy().tobytes())
        weights = rng.normal(0.0, 1.0, (steps, sim.num_nodes, 3))
        grads = sim.backward(dl_dx=weights)
    for key in ("x0", "v0", "attachment_targets", "external_forces"):
        if grads.get(key) is not None:
            h.update(np.ascontiguousarray(grads[key]).tobytes())
    return h.hexdigest()


def check_physics(checkpoint: Mapping[str, Any], engine: Any, where: Path) -> None:
    """Refuses to resume a run whose steps were simulated with other physics or solver settings
    (the rest of it would be another experiment)."""
    saved, now = checkpoint.get("physics"), physics_fingerprint(engine)
    if saved is None or saved == now:
        return
    if saved["solver"] != now["solver"]:
        what = f"solver settings {saved['solver']} -> {now['solver']}"
    elif saved["physics"] != now["physics"]:
        what = "scene physics (mesh, parameters or obstacles)"
    else:  # older checkpoints have no dynamics hash: they cannot show they match
        what = "dynamics (a short probe episode differs: another simulator build or task loss)"
    raise ValueError(f"{where}: its checkpoint was simulated with other {what}; use another run folder "
                     "or resume=False (--fresh) to start again")
