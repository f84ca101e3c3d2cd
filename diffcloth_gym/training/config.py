"""Training configs: TOML files in ``diffcloth_gym/training/configs/`` (package data), found by
name (``load("hat_apg")``) or by path. A method config (``hat_apg``, ``hat_ppo``) holds one
method's hyperparameters; a budget config (``budget_demo``, ``budget_full``) says which
methods run, on which env and seeds, for how many time steps, and may override any method
key under ``[apg]`` / ``[ppo]``. Scene physics never appears here: the env's task and scene
configs own it (an env override such as a solver tolerance goes under ``[env]``)."""

from __future__ import annotations

import copy
import importlib.resources
import tomllib
from pathlib import Path
from typing import Any, Mapping

from diffcloth_gym.errors import ConfigError


def config_names() -> list[str]:
    """Names of the shipped training configs."""
    root = importlib.resources.files("diffcloth_gym.training") / "configs"
    return sorted(p.name[:-5] for p in root.iterdir() if p.name.endswith(".toml"))


def load(name_or_path: str | Path) -> dict[str, Any]:
    """A shipped config by name, or a TOML file by path, as a fresh dict."""
    p = Path(name_or_path)
    if p.suffix == ".toml" and p.exists():
        text = p.read_text()
    else:
        res = importlib.resources.files("diffcloth_gym.training") / "configs" / f"{name_or_path}.toml"
        if not res.is_file():
            raise ConfigError(f"no training config {str(name_or_path)!r}; shipped: {config_names()}")
        text = res.read_text()
    return tomllib.loads(text)


def merged(base: Mapping[str, Any], overrides: Mapping[str, Any] | None) -> dict[str, Any]:
    """``base`` updated by ``overrides`` recursively (tables merge, values replace); a key the
    base does not have is refused, so a typo cannot silently do nothing."""
    out = copy.deepcopy(dict(base))
    for key, value in (overrides or {}).items():
        if key not in out:
            raise ConfigError(f"unknown training option {key!r}; known: {sorted(out)}")
        if isinstance(out[key], dict) and isinstance(value, Mapping) and key != "env":
            out[key] = merged(out[key], value)
        elif key == "env":
            # Env arguments are the env's to check (gym.make refuses unknown ones).
            out[key] = {**out[key], **dict(value)}
        else:
            out[key] = copy.deepcopy(value)
    return out


def method_config(method: str, budget: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The method's config (``budget[method]["config"]``, default ``hat_<method>``) with the
    budget's overrides for it and the budget's ``env_id`` / ``[env]``."""
    section = dict((budget or {}).get(method, {}))
    base = load(section.pop("config", f"hat_{method}"))
    if budget and "env_id" in budget:
        section.setdefault("env_id", budget["env_id"])
    if budget and "env" in budget:
        section["env"] = {**budget["env"], **section.get("env", {})}
    return merged(base, section)
