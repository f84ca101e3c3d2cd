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
    """What a run's simulated steps depend on besides its own config: the env's solver settings
    and a hash of its physics (mesh, masses, parameters, effects, obstacles, contact response).
    Paths are left out, so a checkout elsewhere resumes the same run."""
    sim, scene = engine.template, engine.scene
    h = hashlib.sha1()
    for a in (sim.rest_positions, sim.masses, sim.triangles):
        h.update(np.ascontiguousarray(a).tobytes())
    h.update(json.dumps({"params": sim.params(), "effects": sim.effects, "handles": sim.attachment_nodes,
                         **{k: scene.get(k) for k in ("obstacles", "contact", "self_collision")}},
                        sort_keys=True, default=str).encode())
    return {"solver": sim.solver(), "physics": h.hexdigest()}


def check_physics(checkpoint: Mapping[str, Any], engine: Any, where: Path) -> None:
    """Refuses to resume a run whose steps were simulated with other physics or solver settings
    (the rest of it would be another experiment)."""
    saved, now = checkpoint.get("physics"), physics_fingerprint(engine)
    if saved is None or saved == now:
        return
    what = (f"solver settings {saved['solver']} -> {now['solver']}" if saved["solver"] != now["solver"]
            else "the scene's physics (mesh, parameters or obstacles)")
    raise ValueError(f"{where}: its checkpoint was simulated with other {what}; use another run folder "
                     "or resume=False (--fresh) to start again")
