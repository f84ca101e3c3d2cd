"""diffcloth-gym: a fast differentiable cloth simulator (Rust) for learning and control.

The simulator is projective-dynamics cloth after DiffCloth (Li et al. 2022). Start with
:class:`Simulator`::

    from diffcloth_gym import Simulator
    sim = Simulator.from_config("wind")          # a shipped scene name, a TOML path, or a dict
    sim.step()                                   # one implicit-Euler step
    sim.positions                                # (n, 3) float64
"""

from diffcloth_gym.errors import (
    ConfigError,
    ContactError,
    ConvergenceWarning,
    DiffClothError,
    DivergedError,
    InputError,
    InternalError,
    MeshError,
    ParameterError,
    PenetrationWarning,
    SolverError,
    UnsupportedError,
)
from diffcloth_gym.scenes import CONFIG_DIR, contact_free, load_scene, scene_names
from diffcloth_gym.simulator import Simulator
from diffcloth_gym.envs import register_envs

register_envs()

__all__ = [
    "CONFIG_DIR",
    "ConfigError",
    "ContactError",
    "ConvergenceWarning",
    "DiffClothError",
    "DivergedError",
    "InputError",
    "InternalError",
    "MeshError",
    "ParameterError",
    "PenetrationWarning",
    "Simulator",
    "SolverError",
    "UnsupportedError",
    "contact_free",
    "load_scene",
    "scene_names",
]
