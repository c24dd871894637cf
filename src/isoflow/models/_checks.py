"""Parameter checks shared by the model constructors."""

from __future__ import annotations

import os
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._errors import DtypeError, NonFiniteError, NotInSpaceError, ParameterError, ShapeError

__all__ = [
    "available_memory",
    "check_n",
    "check_separated",
    "check_vortex_input",
    "real_parameter",
    "require_memory",
]

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
        raise NonFiniteError(f"{what} must be finite (found NaN or Inf)")
    return arr


def available_memory() -> int | None:
    """Bytes of memory available to a new allocation now (Linux ``MemAvailable``: free memory
    plus what the kernel can reclaim), or ``None`` where this cannot be told."""
    try:
        import psutil
    except ImportError:
        pass
    else:
        return int(psutil.virtual_memory().available)
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, ValueError, OSError):
        return None


def _size(nbytes: float) -> str:
    return f"{nbytes / 2**30:.1f} GiB" if nbytes >= 2**30 else f"{nbytes / 2**20:.0f} MiB"


def require_memory(state_bytes: float, peak_states: float, what: str) -> None:
    """Refuse to build a model whose construction needs more memory than is available.

    Parameters
    ----------
    state_bytes : float
        Bytes of the model's state.
    peak_states : float
        Peak memory of the construction in states (measured per model).
    what : str
        The model and the parameter that sets the size (``"euler_sphere: N = 20000"``).

    Raises
    ------
    ParameterError
        Naming the estimate and the available memory.
    """
    need = state_bytes * peak_states
    have = available_memory()
    if have is not None and need > have:
        raise ParameterError(
            f"{what} needs about {_size(need)} of memory to build ({peak_states:g} times the "
            f"{_size(state_bytes)} state), more than the {_size(have)} available here; "
            "choose a smaller size"
        )


def check_vortex_input(
    positions: ArrayLike, circulations: ArrayLike, model: str
) -> tuple[Array, Array]:
    """Point vortices' ``(positions, circulations)`` as float arrays: shapes, dtypes,
    finiteness, circulations nonzero. Positions ``(*batch, N, 3)``."""
    pos = real_parameter(positions, f"{model}: positions")
    if pos.ndim < 2 or pos.shape[-1] != 3:
        raise ShapeError(
            f"{model}: positions must have shape (N, 3) (rows are vortices), got {pos.shape}"
        )
    N = pos.shape[-2]
    if N < 1:
        raise ShapeError(f"{model}: at least one vortex is needed, got positions {pos.shape}")
    circ = real_parameter(circulations, f"{model}: circulations")
    if circ.shape != (N,):
        raise ShapeError(
            f"{model}: circulations must have shape ({N},) for {N} vortices, got {circ.shape}"
        )
    if np.any(circ == 0):
        raise ParameterError(
            f"{model}: circulations must be nonzero (a vortex of zero strength is a passive "
            f"tracer, outside this Lie–Poisson model), got {circ}"
        )
    return pos, circ


def check_separated(products: Array, limit: float, model: str, what: str) -> None:
    """Raise if two distinct vortices coincide (``|products_ij - limit|`` tiny)."""
    N = products.shape[-1]
    if N < 2:
        return
    off = ~np.eye(N, dtype=bool)
    gap = np.abs(products - limit)[..., off]
    worst = float(np.min(gap))
    if worst <= 1e-12:
        raise NotInSpaceError(
            f"{model}: two vortices coincide ({what} = {limit:g} up to {worst:.1e}); the phase "
            "space excludes collisions",
            distance=worst,
            tolerance=1e-12,
        )
