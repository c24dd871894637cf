r"""The compiled distance to a matrix space of :mod:`isoflow.algebras` (imported on first use).

For the spaces :math:`V = \{X : X = s\,\bar X^T\}` (``so``: ``s = -1``, ``sym``: ``+1``, ``u``:
``-1``, ``herm``: ``+1``; the conjugation acts on complex entries only), optionally
traceless (``su``), the distance of ``W`` to ``V`` is the Frobenius norm of

.. math::

    W - P(W) = D + t I, \qquad D = \tfrac12 (W - s \bar W^T), \qquad
    t = \tfrac1n \operatorname{Tr} \tfrac12 (W + s \bar W^T) \ \text{(traceless spaces, else 0)}.

:func:`distances` sums it per matrix in one pass, without the temporaries NumPy needs (a
transposed copy and a difference of ``W``'s size); it runs on every saved state of a run
(:func:`isoflow._stepping.stop_members_leaving_the_space`).
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["distances"]


@numba.njit(cache=True, nogil=True)
def distances(W, s, traceless, out):  # type: ignore[no-untyped-def]
    """``out[m] = |W[m] - P(W[m])|_F`` for the matrices ``W`` (``(M, n, n)``), see the module
    docstring."""
    n = W.shape[1]
    for m in range(W.shape[0]):
        A = W[m]
        t = 0.0 * A[0, 0]
        if traceless:
            for i in range(n):
                t += 0.5 * (A[i, i] + s * np.conj(A[i, i]))
            t /= n
        acc = 0.0
        for i in range(n):
            for j in range(n):
                d = 0.5 * (A[i, j] - s * np.conj(A[j, i]))
                if i == j:
                    d += t
                acc += d.real * d.real + d.imag * d.imag
        out[m] = math.sqrt(acc)
