"""The procedural meshes the shipped task scenes load (``dress.toml``, ``tshirt.toml``): which
generator and arguments make each file, and a writer (``scripts/make_task_meshes.py``)."""

from __future__ import annotations

from pathlib import Path

from diffcloth_gym.optim import shapes

#: file name in ``diffcloth_gym/configs/`` -> (generator, keyword arguments).
MESHES = {
    "dress_skirt.obj": (shapes.skirt, {"around": 24, "rings": 8, "waist_radius": 1.0, "length": 3.0,
                                       "half_angle_deg": 60.0}),
    "tshirt_tube.obj": (shapes.flat_tube, {"around": 24, "rings": 12, "width": 3.0, "height": 3.5, "gap": 0.3}),
}


def mesh(name: str):
    """``(vertices, triangles, node sets)`` of the shipped mesh ``name``."""
    gen, kwargs = MESHES[name]
    return gen(**kwargs)


def write_mesh(name: str, folder: Path) -> Path:
    gen, kwargs = MESHES[name]
    v, t, _ = gen(**kwargs)
    header = (f"Procedural mesh for the shipped task scenes: diffcloth_gym.optim.shapes.{gen.__name__}"
              f"({', '.join(f'{k}={v!r}' for k, v in kwargs.items())}); written by scripts/make_task_meshes.py")
    return shapes.write_obj(Path(folder) / name, v, t, header)


def write_all(folder: str | Path | None = None) -> list[Path]:
    folder = Path(__file__).resolve().parents[1] / "configs" if folder is None else Path(folder)
    return [write_mesh(name, folder) for name in MESHES]
