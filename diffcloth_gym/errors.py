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


class UnsupportedError(DiffClothError, NotImplementedError):
    """The request is valid but not supported yet (the message says what)."""


class InternalError(DiffClothError, RuntimeError):
    """A bug inside the simulator (a Rust panic caught at the boundary). Please report it."""


class ConvergenceWarning(UserWarning):
    """A step stopped at its iteration cap above its tolerance (``solver.tolerance > 0``): the
    state is not the implicit-Euler solution, and with contact the contact law (and the
    non-penetration it implies) holds only approximately. Raise ``solver.max_iterations``, or
    see ``profile()["unconverged_steps"]``."""
