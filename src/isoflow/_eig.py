"""Eigenvalues of stacks of Hermitian matrices, computed without holding the GIL.

The Casimirs of the matrix spaces are eigenvalues; the time loop computes them for the saved
states in its writer thread while the next chunk steps (:mod:`isoflow._solve`). NumPy's
``eigvalsh`` holds the GIL for a whole stack, which would stall the stepping thread at its next
call; this loop (LAPACK's ``heevd``/``syevd`` through numba, ``nogil``) does not. It gives the
same numbers as :func:`numpy.linalg.eigvalsh` (ascending; LAPACK's same routine), and every
Casimir of a run goes through it, so drifts compare like with like.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["eigvalsh"]


#: Smallest stack whose eigenvalues are spread over numba threads (from the main thread only:
#: the writer thread shares the machine with the stepping thread).
PARALLEL_MIN = 256


def eigvalsh(A: Any) -> NDArray[np.float64]:
    """Ascending eigenvalues of the Hermitian (real symmetric) matrices ``A`` ``(..., n, n)``."""
    import threading

    import numba

    from ._eig_compiled import eigvalsh_stack, eigvalsh_stack_parallel

    A = np.asarray(A)
    n = A.shape[-1]
    flat = np.ascontiguousarray(A.reshape(-1, n, n))
    if flat.dtype.kind not in "fc":
        flat = flat.astype(np.float64)
    out = np.empty(flat.shape[:2], dtype=np.float64)
    if (
        flat.shape[0] >= PARALLEL_MIN
        and numba.get_num_threads() > 1
        and (threading.current_thread() is threading.main_thread())
    ):
        eigvalsh_stack_parallel(flat, out)
    elif flat.shape[0]:
        eigvalsh_stack(flat, out)
    return out.reshape(*A.shape[:-2], n)
