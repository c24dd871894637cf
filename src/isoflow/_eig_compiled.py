"""The compiled loops of :mod:`isoflow._eig` (imported on first use)."""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["eigvalsh_stack", "eigvalsh_stack_parallel"]


def _loop(A, out):  # type: ignore[no-untyped-def]
    for m in numba.prange(A.shape[0]):
        out[m] = np.linalg.eigvalsh(A[m])


# two compilations of one loop (numba's cache key ignores ``parallel=``: separate functions)
eigvalsh_stack = numba.njit(cache=True, nogil=True)(_loop)
eigvalsh_stack.__doc__ = "``out[m] = eigvalsh(A[m])`` for every matrix, without the GIL."


def _loop_parallel(A, out):  # type: ignore[no-untyped-def]
    for m in numba.prange(A.shape[0]):
        out[m] = np.linalg.eigvalsh(A[m])


eigvalsh_stack_parallel = numba.njit(cache=True, nogil=True, parallel=True)(_loop_parallel)
eigvalsh_stack_parallel.__doc__ = "The same over numba threads (large stacks, main thread)."
