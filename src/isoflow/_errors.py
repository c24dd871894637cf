"""Exception hierarchy of isoflow.

Every error raised on purpose by the library derives from :class:`IsoflowError` and, where one
fits, from the matching builtin (``ValueError``, ``TypeError``, ``RuntimeError``), so that both
``except iso.IsoflowError`` and ``except ValueError`` catch bad input.
"""

from __future__ import annotations

__all__ = [
    "ArgumentTypeError",
    "ConvergenceError",
    "DtypeError",
    "InvalidBError",
    "IsoflowError",
    "ModelChangedError",
    "NonFiniteError",
    "NotInSpaceError",
    "ParameterError",
    "ResultFileError",
    "ResultWriteError",
    "ShapeError",
    "StepSizeError",
    "TimeSpanError",
    "UnsupportedAlgebraError",
]


class IsoflowError(Exception):
    """Base class of every error isoflow raises on purpose."""


class ShapeError(IsoflowError, ValueError):
    """An array has the wrong shape (a state, the output of ``B``, a coordinate vector)."""


class DtypeError(IsoflowError, TypeError):
    """An array has a dtype the space cannot hold (e.g. complex data for a real algebra)."""


class NonFiniteError(IsoflowError, ValueError):
    """An array holds NaN or Inf where finite numbers are required."""


class NotInSpaceError(IsoflowError, ValueError):
    """A matrix is farther from its space than the tolerance allows.

    Attributes
    ----------
    distance : float
        Largest Frobenius distance to the space over the ensemble.
    tolerance : float
        The tolerance it was compared with.
    """

    def __init__(self, message: str, *, distance: float, tolerance: float) -> None:
        super().__init__(message)
        self.distance = distance
        self.tolerance = tolerance


class ParameterError(IsoflowError, ValueError):
    """A model, space or method parameter is out of range or malformed (e.g. ``n < 1``)."""


class ArgumentTypeError(IsoflowError, TypeError):
    """An argument of the wrong kind: not a problem, a method, an algebra, a callable ``B``,
    a numba-compiled function where the argument names one."""


class UnsupportedAlgebraError(IsoflowError, TypeError):
    """A method was applied to a problem on a space it is not defined for."""


class InvalidBError(IsoflowError, ValueError):
    """The map ``B`` of a problem returned something unusable.

    Raised when ``B(W)`` has the wrong shape or dtype, holds non-finite numbers, or lies outside
    the normalizer algebra ``N(V)`` that the isospectral flow ``W' = [B(W), W]`` requires.
    """


class ResultFileError(IsoflowError, OSError):
    """A path is not a usable isoflow result file.

    Missing, not HDF5, not ours, truncated, damaged (a checksum does not match), crafted (a
    field out of range), locked by a live writer, or not a regular file where one is replaced.
    """


class ModelChangedError(ResultFileError):
    """A resume found another model than the one the result file's run started with.

    The model's ``B`` (or a function of its diagnostics) differs at the fingerprint's probe
    state, or the source of the user code defining it changed; resuming would mix two flows
    in one file. ``force=True`` (``isoflow run --resume FILE --force``) resumes anyway.

    Attributes
    ----------
    changes : list of str
        What differs, in words.
    """

    def __init__(self, message: str, *, changes: list[str]) -> None:
        super().__init__(message)
        self.changes = changes


class ResultWriteError(IsoflowError, OSError):
    """Writing a result file failed (disk full, permissions, ...).

    The run stops; the file keeps the run up to its last checkpoint and can be resumed.
    """


class StepSizeError(IsoflowError, ValueError):
    """The step size is not positive and finite, or does not divide the time span."""


class TimeSpanError(IsoflowError, ValueError):
    """The time span is empty, reversed or not finite."""


class ConvergenceError(IsoflowError, RuntimeError):
    """The nonlinear solve of an implicit step did not converge.

    Attributes
    ----------
    step : int
        Index of the step that failed (0 for the step from ``t0``, ``k`` for the step from
        ``t0 + k dt``).
    time : float
        Time at the start of the failed step.
    residual : float
        Largest final residual over the ensemble.
    iterations : int
        Iterations spent on the failed step.
    reason : str
        ``"max_iter"``, ``"diverged"`` or ``"non_finite"``.
    """

    def __init__(
        self,
        message: str,
        *,
        step: int = 0,
        time: float = float("nan"),
        residual: float = float("nan"),
        iterations: int = 0,
        reason: str = "max_iter",
    ) -> None:
        super().__init__(message)
        self.step = step
        self.time = time
        self.residual = residual
        self.iterations = iterations
        self.reason = reason
