"""diffcloth-gym: a fast differentiable cloth simulator (Rust) for learning and control.

The simulator is projective-dynamics cloth after DiffCloth (Li et al. 2022). Start with
:class:`Simulator`::

    from diffcloth_gym import Simulator
    sim = Simulator.from_config("wind")          # a name in configs/, a path, or a dict
    sim.step()                                   # one implicit-Euler step
    sim.positions                                # (n, 3) float64
"""

from diffcloth_gym.errors import (
    ConfigError,
    ConvergenceWarning,
    DiffClothError,
    DivergedError,
    InputError,
    InternalError,
    MeshError,
    ParameterError,
    SolverError,
    UnsupportedError,
)
from diffcloth_gym.simulator import CONFIG_DIR, Simulator

__all__ = [
    "CONFIG_DIR",
    "ConfigError",
    "ConvergenceWarning",
    "DiffClothError",
    "DivergedError",
    "InputError",
    "InternalError",
    "MeshError",
    "ParameterError",
    "Simulator",
    "SolverError",
    "UnsupportedError",
]
