"""Parameter checks shared by the model constructors."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._errors import DtypeError, NonFiniteError, ParameterError

__all__ = ["check_n", "real_parameter"]

Array = NDArray[Any]


def check_n(n: Any, minimum: int, model: str) -> int:
    """Validate a matrix size ``n >= minimum`` (a positive integer, not a bool)."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)):
        raise ParameterError(f"{model}: n must be an integer, got {n!r}")
    if n < minimum:
        raise ParameterError(f"{model}: n must be >= {minimum}, got {n}")
    return int(n)


def real_parameter(value: ArrayLike, what: str) -> Array:
    """``value`` as a finite float64 array; rejects non-numeric, complex and NaN/Inf input."""
    arr = np.asarray(value)
    if arr.dtype.kind not in "iuf":
        raise DtypeError(f"{what} must be real numbers, got an array of dtype {arr.dtype}")
    arr = arr.astype(np.float64)
    if not np.all(np.isfinite(arr)):
        raise NonFiniteError(f"All entries of {what} must be finite (found NaN or Inf).")
    return arr
