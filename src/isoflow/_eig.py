"""Eigenvalues of stacks of Hermitian matrices, computed without holding the GIL.

The Casimirs of the matrix spaces are eigenvalues; the time loop computes them for the saved
states in its writer thread while the next chunk steps (:mod:`isoflow._solve`). NumPy's
``eigvalsh`` holds the GIL for a whole stack, which would stall the stepping thread at its next
call; this loop (LAPACK's ``heevd``/``syevd`` through numba, ``nogil``) does not. It gives the
same numbers as :func:`numpy.linalg.eigvalsh` (ascending; LAPACK's same routine), and every
Casimir of a run goes through it, so drifts compare like with like. The real skew matrices of
``so(n)`` take a real route to the eigenvalues of :math:`iW` (:func:`skew_eigvalsh`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["eigh_diagonal", "eigvalsh", "skew_eigvalsh"]


#: Smallest stack whose eigenvalues are spread over numba threads (from the main thread only:
#: the writer thread shares the machine with the stepping thread).
PARALLEL_MIN = 256

#: Largest ``n`` whose skew eigenvalues take the real route of :func:`skew_eigvalsh` (measured:
#: 0.6x the complex route at n = 10, 0.8x at 128, even at 256, 1.4x at 512).
SKEW_MAX = 192


def eigvalsh(A: Any) -> NDArray[np.float64]:
    """Ascending eigenvalues of the Hermitian (real symmetric) matrices ``A`` ``(..., n, n)``."""
    from ._eig_compiled import eigvalsh_stack, eigvalsh_stack_parallel

    A = np.asarray(A)
    flat = _stack(A)
    if flat.dtype.kind not in "fc":
        flat = flat.astype(np.float64)
    return _run(eigvalsh_stack, eigvalsh_stack_parallel, flat).reshape(A.shape[:-1])


def skew_eigvalsh(W: Any) -> NDArray[np.float64]:
    r"""Ascending eigenvalues of :math:`iW` for real skew matrices ``W`` ``(..., n, n)``.

    The same numbers as ``eigvalsh(1j * W)`` to rounding (a few :math:`\epsilon |W|`),
    computed in real arithmetic: a Householder reduction of ``W`` to skew tridiagonal form,
    whose :math:`i` multiple is similar to a real symmetric tridiagonal matrix (see
    :func:`isoflow._eig_compiled.skew_to_tridiagonal`), whose eigenvalues LAPACK computes. For
    the ``10 x 10`` states of the rigid body this takes 0.6 of the time of the complex route
    (the call overhead of LAPACK dominates at this size, and the real call's is smaller); an
    ensemble computes these for every saved member. Above :data:`SKEW_MAX` LAPACK's blocked
    complex routine is faster and is used instead (one route per size, so a run's Casimirs
    all come from the same one).
    """
    from ._eig_compiled import skew_eigvalsh_stack, skew_eigvalsh_stack_parallel

    W = np.asarray(W)
    if W.shape[-1] > SKEW_MAX or np.iscomplexobj(W):
        return eigvalsh(1j * W)
    if W.dtype.kind != "f":
        W = W.astype(np.float64)
    flat = _stack(W)
    return _run(skew_eigvalsh_stack, skew_eigvalsh_stack_parallel, flat).reshape(W.shape[:-1])


def eigh_diagonal(A: Any, B: Any) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    r"""Eigenvalues of the Hermitian ``A`` and the diagonal of ``B`` in its eigenvectors.

    For stacks ``(..., n, n)`` of Hermitian ``A`` and ``B``: the ascending eigenvalues
    :math:`\lambda_i` of ``A`` and :math:`d_i = \operatorname{Re}(U^\dagger B U)_{ii}` with ``U``
    the unit eigenvectors (LAPACK's ``heevd`` through numba, without the GIL, like
    :func:`eigvalsh`). Sums :math:`\sum_i d_i f(\lambda_i) = \operatorname{Tr}(B f(A))` do not
    depend on the choice of eigenvectors within a repeated eigenvalue; the single :math:`d_i`
    do. (Used for the cross Casimirs :math:`\operatorname{Tr}(W\Theta^k)` of the semidirect
    products, :mod:`isoflow.algebras.semidirect`.)
    """
    from ._eig_compiled import eigh_diagonal_stack

    A = np.asarray(A, dtype=np.complex128)
    B = np.asarray(B, dtype=np.complex128)
    flat_a, flat_b = _stack(A), _stack(np.broadcast_to(B, A.shape))
    lam = np.empty(flat_a.shape[:2])
    d = np.empty(flat_a.shape[:2])
    if flat_a.shape[0]:
        eigh_diagonal_stack(flat_a, flat_b, lam, d)
    return lam.reshape(A.shape[:-1]), d.reshape(A.shape[:-1])


def _stack(A: NDArray[Any]) -> NDArray[Any]:
    n = A.shape[-1]
    return np.ascontiguousarray(A.reshape(-1, n, n))


def _run(serial: Any, parallel: Any, flat: NDArray[Any]) -> NDArray[np.float64]:
    """``out[m]`` = the eigenvalues of ``flat[m]`` by ``serial`` or, for a large stack on the
    main thread with numba threads to spare, by ``parallel``."""
    import threading

    import numba

    from ._compile_clock import compile_notice

    out = np.empty(flat.shape[:2], dtype=np.float64)
    with compile_notice("the eigenvalue routine of the Casimir diagnostics"):
        if (
            flat.shape[0] >= PARALLEL_MIN
            and numba.get_num_threads() > 1
            and (threading.current_thread() is threading.main_thread())
        ):
            parallel(flat, out)
        elif flat.shape[0]:
            serial(flat, out)
    return out
