"""Procedural garment meshes for the paper's T-shirt and Dress tasks, where a simple shape
serves: a skirt is a cone of cloth, a T-shirt's body a flat tube (a front and a back layer
joined at the sides). The shipped task scenes load them as OBJ files written by
:func:`write_obj` (``scripts/make_task_meshes.py``), so the scenes are plain TOML files.

Both generators return ``(vertices (n, 3), triangles (t, 3))`` and the node sets a task needs.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from diffcloth_gym.errors import InputError


def _count(name: str, value, low: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
        raise InputError(f"{name} must be an integer >= {low}, got {value!r}")
    return int(value)


def _positive(name: str, value) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a positive number, got {value!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise InputError(f"{name} must be a positive number, got {value!r}")
    return v


def _ring_strip(rings: int, around: int) -> np.ndarray:
    """Triangles joining ``rings`` closed rings of ``around`` nodes (node ``r * around + i``),
    the quads' diagonals alternating so the mesh has no preferred shear direction."""
    tris = []
    for r in range(rings - 1):
        for i in range(around):
            a, b = r * around + i, r * around + (i + 1) % around
            c, d = a + around, b + around
            if (r + i) % 2 == 0:
                tris += [(a, c, b), (b, c, d)]
            else:
                tris += [(a, c, d), (a, d, b)]
    return np.asarray(tris, dtype=np.int64)


def skirt(around: int = 24, rings: int = 8, waist_radius: float = 1.0, length: float = 3.0,
          half_angle_deg: float = 60.0) -> tuple[np.ndarray, np.ndarray, dict]:
    """A skirt: the side of a truncated cone around the y axis, its waist ring (radius
    ``waist_radius``) at y = 0 and its hem ``length`` further along the cone's generators,
    which open at ``half_angle_deg`` from the downward vertical (the rest shape: the widest
    the skirt flares without stretching). ``rings`` rings of ``around`` nodes, waist first.

    Returns vertices, triangles and ``{"waist": nodes, "hem": nodes}``."""
    around = _count("around", around, 3)
    rings = _count("rings", rings, 2)
    rw, L = _positive("waist_radius", waist_radius), _positive("length", length)
    a = math.radians(float(half_angle_deg))
    if not 0 < a < math.pi / 2:
        raise InputError(f"half_angle_deg must be in (0, 90), got {half_angle_deg!r}")
    s = np.linspace(0.0, L, rings)
    phi = 2 * np.pi * np.arange(around) / around
    r = np.broadcast_to(rw + s[:, None] * math.sin(a), (rings, around))
    v = np.stack([r * np.cos(phi), np.broadcast_to(-s[:, None] * math.cos(a), r.shape), r * np.sin(phi)], axis=-1)
    nodes = np.arange(rings * around).reshape(rings, around)
    return v.reshape(-1, 3), _ring_strip(rings, around), {"waist": nodes[0].tolist(), "hem": nodes[-1].tolist()}


def flat_tube(around: int = 24, rings: int = 12, width: float = 3.0, height: float = 3.5,
              gap: float = 0.3) -> tuple[np.ndarray, np.ndarray, dict]:
    """A T-shirt's body as a flat tube, open at the top and the bottom: a stadium-shaped cross
    section (two flat layers ``gap`` apart joined by half circles at the sides), ``width``
    wide across the layers, in the x-y plane, its top ring at y = 0 and its bottom at
    ``-height``. ``around`` nodes per ring (even), ``rings`` rings, top first.

    Returns vertices, triangles and ``{"shoulders": the two top nodes at the sides (x -/+),
    "top": the top ring}``."""
    around = _count("around", around, 8)
    if around % 2:
        raise InputError(f"around must be even (a node at each side), got {around}")
    rings = _count("rings", rings, 2)
    w, hgt, g = _positive("width", width), _positive("height", height), _positive("gap", gap)
    if not g < w:
        raise InputError(f"gap ({g}) must be smaller than width ({w})")
    # Stadium perimeter: two straight layers of length w - g and two half circles of radius g/2.
    straight, radius = w - g, g / 2
    perimeter = 2 * straight + 2 * math.pi * radius
    t = perimeter * np.arange(around) / around
    # Start at the -x side's middle, walk the front layer (z = +g/2) towards +x.
    pts = []
    for u in t:
        if u < math.pi * radius / 2:                                   # quarter circle, -x side
            th = math.pi - u / radius
            pts.append((-straight / 2 + radius * math.cos(th), radius * math.sin(th)))
        elif u < math.pi * radius / 2 + straight:                        # front layer
            pts.append((-straight / 2 + (u - math.pi * radius / 2), radius))
        elif u < 3 * math.pi * radius / 2 + straight:                    # half circle, +x side
            th = math.pi / 2 - (u - math.pi * radius / 2 - straight) / radius
            pts.append((straight / 2 + radius * math.cos(th), radius * math.sin(th)))
        elif u < 3 * math.pi * radius / 2 + 2 * straight:                # back layer
            pts.append((straight / 2 - (u - 3 * math.pi * radius / 2 - straight), -radius))
        else:                                                            # quarter circle back to -x
            th = -math.pi / 2 - (u - 3 * math.pi * radius / 2 - 2 * straight) / radius
            pts.append((-straight / 2 + radius * math.cos(th), radius * math.sin(th)))
    ring = np.asarray(pts)
    y = np.linspace(0.0, -hgt, rings)
    v = np.stack([np.broadcast_to(ring[:, 0], (rings, around)), np.broadcast_to(y[:, None], (rings, around)),
                  np.broadcast_to(ring[:, 1], (rings, around))], axis=-1).reshape(-1, 3)
    left = int(np.argmin(ring[:, 0]))
    right = int(np.argmax(ring[:, 0]))
    return v, _ring_strip(rings, around), {"shoulders": [left, right], "top": list(range(around))}


def write_obj(path: str | Path, vertices: np.ndarray, triangles: np.ndarray, header: str = "") -> Path:
    """Writes a Wavefront OBJ (1-based faces), numbers rounded to 1e-9 so the file is stable."""
    path = Path(path)
    lines = [f"# {line}" for line in header.splitlines()]
    lines += [f"v {x:.9f} {y:.9f} {z:.9f}".replace("-0.000000000", "0.000000000") for x, y, z in vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in triangles]
    path.write_text("\n".join(lines) + "\n")
    return path
