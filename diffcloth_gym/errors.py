"""Exceptions raised by diffcloth-gym. Bad input is a ``ValueError`` subclass."""


class DiffClothError(Exception):
    """Base class of every diffcloth-gym error."""


class InvalidInputError(DiffClothError, ValueError):
    """Something the caller passed is invalid (config, mesh, array, parameter)."""


class ConfigError(InvalidInputError):
    """A scene config is malformed: unknown key, missing field, bad value, unreadable file."""


class MeshError(InvalidInputError):
    """A mesh cannot be simulated: index out of range, degenerate triangle, non-finite vertex."""


class InputError(InvalidInputError):
    """A per-step input has the wrong shape or contains NaN/inf."""


class ParameterError(InvalidInputError):
    """A physical parameter or solver setting is out of range or unknown."""


class SolverError(DiffClothError, RuntimeError):
    """A factorization or linear solve failed."""


class DivergedError(SolverError):
    """The state became non-finite; the step was rolled back, the simulator stays usable."""


class ContactError(SolverError):
    """A step could not keep the cloth out of an obstacle (a node kept crossing it after
    repeated re-detection of the step's contacts); the step was rolled back, the simulator
    stays usable. A smaller time step ``h`` helps."""


class UnsupportedError(DiffClothError, NotImplementedError):
    """The request is valid but not supported yet (the message says what)."""


class InternalError(DiffClothError, RuntimeError):
    """A bug inside the simulator (a Rust panic caught at the boundary). Please report it."""


class ConvergenceWarning(UserWarning):
    """A step stopped at its iteration cap above its tolerance (``solver.tolerance > 0``): the
    state is not the implicit-Euler solution, and with contact the contact law (and the
    non-penetration it implies) holds only approximately. Raise ``solver.max_iterations``, or
    see ``profile()["unconverged_steps"]``."""


class PenetrationWarning(UserWarning):
    """The state starts with nodes inside an obstacle, or with self-contact pairs closer than
    the contact radius (a cloth folded exactly onto itself). The contact law closes such an
    overlap within one step, so the first step throws those nodes out at up to depth / h and
    the cloth gains kinetic energy it never had (10 m inside a plane at h = 0.01: 1000 m/s).
    Raised by construction and :meth:`~diffcloth_gym.Simulator.reset`; the message names the
    deepest node, its depth and the speed. Start the cloth outside the obstacles and its layers
    at least the self-contact radius apart."""
