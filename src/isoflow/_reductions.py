r"""Sums over a matrix's entries whose value for one member does not depend on the batch.

The diagnostics of a run are computed on the saved rows a chunk hands over: the same state is
one row of many in a run and the first row alone after a resume. ``np.einsum`` picks its inner
loop by the shapes of the whole call, so ``einsum("kab,kab->k", ...)`` gave an energy that
differed in its last bits between the two (measured: every row of a 41-row batch against the
rows one by one), and a resumed file's diagnostics were not the uninterrupted run's. Here each
member's entries are multiplied and then summed as one contiguous row (NumPy's pairwise sum,
the same for the row whatever else is in the call), in blocks of members of bounded size;
``np.trace`` of a stack differed the same way from the trace of one matrix, and :func:`trace`
sums a contiguous copy of each diagonal.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["real_inner", "sum_of_squares", "trace"]

#: Entries per block of members (bounded temporaries).
_BLOCK_ENTRIES = 1 << 22


def real_inner(A: Any, B: Any) -> NDArray[np.float64]:
    r""":math:`\operatorname{Re}\sum_{ij} \bar A_{ij} B_{ij}` over the last two axes.

    Parameters
    ----------
    A, B : ndarray, shape (*batch, n, m)
        Real or complex, of one shape.

    Returns
    -------
    ndarray, shape batch
        Each member's sum, the same bits whatever the batch it is computed in.
    """
    A = np.asarray(A)
    B = np.asarray(B)
    batch, size = A.shape[:-2], A.shape[-2] * A.shape[-1]
    a = np.ascontiguousarray(A).reshape(-1, size)
    b = np.ascontiguousarray(B).reshape(-1, size)
    out = np.empty(a.shape[0])
    step = max(1, _BLOCK_ENTRIES // max(size, 1))
    for k0 in range(0, a.shape[0], step):
        x, y = a[k0 : k0 + step], b[k0 : k0 + step]
        if np.iscomplexobj(x) or np.iscomplexobj(y):
            prod = x.real * y.real + x.imag * y.imag
        else:
            prod = x * y
        out[k0 : k0 + step] = prod.sum(axis=1)
    return out.reshape(batch)


def sum_of_squares(M: Any) -> NDArray[np.float64]:
    r""":math:`\sum_{ij} |M_{ij}|^2` over the last two axes (see :func:`real_inner`)."""
    return real_inner(M, M)


def trace(M: Any) -> NDArray[Any]:
    """The trace over the last two axes, each member's diagonal summed as one contiguous row
    (see the module docstring)."""
    d = np.ascontiguousarray(np.diagonal(np.asarray(M), axis1=-2, axis2=-1))
    return d.sum(axis=-1)
