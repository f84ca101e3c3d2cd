"""Scene configs: the shipped scenes (package data in ``diffcloth_gym/configs/``), loading a
scene by name, TOML path or dict, and a contact-free copy of a scene."""

from __future__ import annotations

import copy
import tomllib
from importlib.resources import files
from importlib.resources.abc import Traversable
from pathlib import Path
from typing import Any, Mapping

from diffcloth_gym.errors import ConfigError

#: Folder of the shipped scene configs (package data, so it is found from an installed
#: package too). A :class:`~importlib.resources.abc.Traversable`; a :class:`~pathlib.Path`
#: whenever the package is installed as files (the usual case).
CONFIG_DIR: Traversable = files("diffcloth_gym") / "configs"

#: Effects and config tables that make a scene a contact scene (see :func:`contact_free`).
CONTACT_EFFECTS = ("obstacle_contact", "friction", "self_collision")
CONTACT_KEYS = ("obstacles", "self_collision", "contact")


def scene_names() -> list[str]:
    """Names of the shipped scenes, sorted (``["bowl", "hat", ...]``)."""
    return sorted(p.name.removesuffix(".toml") for p in CONFIG_DIR.iterdir() if p.name.endswith(".toml"))


def load_config(config: str | Path | Mapping[str, Any]) -> tuple[dict, Path]:
    """Returns ``(config dict, base folder for relative paths in it)``.

    ``config`` is a shipped scene name (``"wind"``, see :func:`scene_names`), a path to a TOML
    file, or a dict with the same structure as the TOML files (its base is the working folder).
    An unknown name raises :class:`~diffcloth_gym.errors.ConfigError` listing the shipped ones.
    """
    if not isinstance(config, (str, Path, Mapping)):
        raise ConfigError(
            f"config must be a scene name, a TOML path or a dict, got {type(config).__name__}")
    if isinstance(config, Mapping):
        return dict(config), Path.cwd()
    path = Path(config)
    if not path.suffix and not path.exists():
        packaged = CONFIG_DIR / f"{config}.toml"
        if not packaged.is_file():
            raise ConfigError(f"no scene config {str(config)!r} (not a file; shipped scenes: {scene_names()})")
        # Shipped scenes use no relative paths; their base is their folder when it is one.
        base = packaged.resolve().parent if isinstance(packaged, Path) else Path.cwd()
        return _parse(packaged.read_bytes(), packaged), base
    if not path.is_file():
        raise ConfigError(f"no scene config {str(config)!r} (not a file; shipped scenes: {scene_names()})")
    return _parse(path.read_bytes(), path), path.resolve().parent


def _parse(data: bytes, origin: Any) -> dict:
    """Parses a TOML file's bytes; every way it can be malformed is a ConfigError naming it."""
    try:
        # utf-8-sig: a byte-order mark (some Windows editors write one) is not part of TOML.
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise ConfigError(f"{origin}: not UTF-8 text (byte {e.start}: {data[e.start:e.start + 1]!r})") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{origin}: {e}") from None
    except RecursionError:
        # tomllib recurses once per nesting level of arrays and inline tables.
        raise ConfigError(f"{origin}: arrays or tables are nested too deeply") from None


def load_scene(config: str | Path | Mapping[str, Any], **mesh: Any) -> dict:
    """A scene config as a fresh dict (safe to modify): a shipped scene name, a TOML path or a
    dict (copied; a relative OBJ mesh path is made absolute against the file's folder). ``mesh`` keywords override entries of its ``[mesh]`` table, e.g. a grid's
    resolution: ``load_scene("wind", rows=24, cols=24)``."""
    cfg, base = load_config(config)
    cfg = copy.deepcopy(cfg)
    # A relative OBJ path is relative to the file's folder: made absolute, so the dict builds
    # the same mesh from any working folder (a dict's own base is the working folder).
    m = cfg.get("mesh")
    if isinstance(m, dict) and m.get("kind") == "obj" and isinstance(m.get("path"), str) \
            and not Path(m["path"]).is_absolute():
        m["path"] = str(base / m["path"])
    if mesh:
        cfg.setdefault("mesh", {}).update(mesh)
    return cfg


def contact_free(cfg: Mapping[str, Any]) -> dict:
    """A copy of ``cfg`` without obstacles, friction and self-collision (the hat hanging from
    its handles, the sock without the leg): isolates the cloth solver and its adjoint. The
    rest of the scene (mesh, material, attachments, time step) is unchanged."""
    out = copy.deepcopy(dict(cfg))
    out["effects"] = [e for e in out.get("effects", []) if e not in CONTACT_EFFECTS]
    for key in CONTACT_KEYS:
        out.pop(key, None)
    return out
