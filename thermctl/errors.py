"""Exceptions and warnings of thermctl.

Every exception subclasses a built-in so callers can catch it generically,
and every message names the file, zone, column or parameter at fault and says
what was expected and what was found.
"""

__all__ = [
    "ThermctlError",
    "SpecError",
    "DataError",
    "ModelError",
    "EstimationError",
    "ConvergenceWarning",
    "BoundWarning",
    "SpecWarning",
    "DataWarning",
    "ThermctlInternalWarning",
]


class ThermctlError(Exception):
    """Base class of thermctl's exceptions (the CLI turns these into one-line errors)."""


class SpecError(ThermctlError, ValueError):
    """A building spec is malformed or physically invalid."""


class DataError(ThermctlError, ValueError):
    """Measured data cannot be read or does not match the spec."""


class ModelError(ThermctlError, ValueError):
    """A model operation got inconsistent inputs (shapes, names, operating point)."""


class EstimationError(ThermctlError, RuntimeError):
    """Parameter estimation failed (solver failure, non-finite cost, blow-up)."""


class ConvergenceWarning(UserWarning):
    """An iterative solver stopped before converging."""


class BoundWarning(UserWarning):
    """An estimate lies on a bound: the criterion, not the building, chose it."""


class SpecWarning(UserWarning):
    """A spec is valid but probably not what the user meant."""


class DataWarning(UserWarning):
    """Data were repaired or partly dropped."""


class ThermctlInternalWarning(UserWarning):
    """Should never be raised; turned into an error in the test suite."""
