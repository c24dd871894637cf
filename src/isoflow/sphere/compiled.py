r"""Numba-compiled kernels of the Hoppe–Yau Laplacian on one ``(N, N)`` complex matrix.

These are the hot functions of Zeitlin's model, written for compiled time loops: each works on
**one** C-contiguous ``(N, N)`` ``complex128`` matrix and takes its precomputed coefficients
as plain arrays (from :func:`isoflow.sphere.laplacian_coefficients`), so it can be called from
other ``@numba.njit`` code. Importing this module imports numba; :mod:`isoflow.sphere` itself
does not.

The operator (see :mod:`isoflow.sphere` for the derivation)
-----------------------------------------------------------
With rows and columns indexed by ``a, b = 0..N-1``,

.. math::

    (\Delta_N W)_{ab} = \big(2ab - (N-1)(a+b+1)\big) W_{ab}
        + \gamma_a\gamma_b\, W_{a-1,b-1} + \gamma_{a+1}\gamma_{b+1}\, W_{a+1,b+1},
    \qquad \gamma_a = \sqrt{a (N-a)}

(``gamma_0 = gamma_N = 0``). It couples an entry only to its two neighbours on the same
diagonal: on each of the ``2N - 1`` diagonals it is a symmetric tridiagonal matrix, and the
kernels sweep the matrix row by row (every diagonal at once) so that memory is read in order.

The Poisson solve uses the :math:`LDL^T` factorization of each diagonal's tridiagonal block
(no pivoting: every block is negative definite, except the main diagonal's, see
:func:`poisson_solve`), stored "in position": ``mult[a, b]`` is the multiplier that couples
entry ``(a, b)`` to ``(a-1, b-1)`` and ``inv_piv[a, b]`` the inverse pivot of entry
``(a, b)``; both are symmetric ``(N, N)`` arrays, ``O(N^2)`` storage, and a solve costs about
``6 N^2`` real multiply–adds.
"""

from __future__ import annotations

import numba

__all__ = [
    "euler_field",
    "laplacian_apply",
    "laplacian_apply_batch",
    "mhd_field",
    "poisson_solve",
    "poisson_solve_batch",
]


@numba.njit(cache=True)
def laplacian_apply(W, out, diag, gamma):  # type: ignore[no-untyped-def]
    r"""``out = Delta_N W`` for one ``(N, N)`` complex matrix (any matrix, not only ``u(N)``).

    Parameters
    ----------
    W : complex128[N, N]
    out : complex128[N, N]
        Written entirely; must not be ``W``.
    diag : float64[N, N]
        The diagonal coefficients :math:`2ab - (N-1)(a+b+1)`.
    gamma : float64[N + 1]
        :math:`\gamma_a = \sqrt{a (N-a)}`, ``a = 0..N`` (zero at both ends).
    """
    N = W.shape[0]
    for a in range(N):
        ga = gamma[a]
        ga1 = gamma[a + 1]
        for b in range(N):
            v = diag[a, b] * W[a, b]
            if a > 0 and b > 0:
                v += ga * gamma[b] * W[a - 1, b - 1]
            if a < N - 1 and b < N - 1:
                v += ga1 * gamma[b + 1] * W[a + 1, b + 1]
            out[a, b] = v


@numba.njit(cache=True)
def poisson_solve(W, out, inv_piv, mult):  # type: ignore[no-untyped-def]
    r"""``out = P``: the traceless solution of :math:`\Delta_N P = W - \tfrac{\operatorname{Tr}
    W}{N} I` for one ``(N, N)`` complex matrix.

    The trace part of ``W`` (the kernel of :math:`\Delta_N`) is removed first, so ``W`` may
    be any element of ``u(N)`` (or any complex matrix); ``out`` is traceless and, for ``W``
    skew-Hermitian, in ``su(N)``.

    Each diagonal is one tridiagonal solve :math:`L D L^T x = y` (forward sweep
    :math:`z_i = y_i - \ell_i z_{i-1}`, backward sweep :math:`x_i = z_i/\delta_i -
    \ell_{i+1} x_{i+1}`), all diagonals in one row-by-row pass each way. The main diagonal's
    block is singular (its kernel is the identity): its last pivot is skipped
    (``inv_piv[N-1, N-1] = 0``), which solves the first ``N - 1`` equations with
    :math:`x_{N-1} = 0`; the last equation then holds because the right-hand side has zero
    sum, and the mean of the solution is subtracted to make it traceless. The leading
    ``(N-1)``-block is definite, so this is as stable as the other solves.

    Parameters
    ----------
    W : complex128[N, N]
    out : complex128[N, N]
        Written entirely; may not be ``W``.
    inv_piv, mult : float64[N, N]
        The factorization from :func:`isoflow.sphere.laplacian_coefficients`.
    """
    N = W.shape[0]
    tr = 0.0j
    for a in range(N):
        tr += W[a, a]
    mean = tr / N
    # forward sweep, row by row: z[a, b] = y[a, b] - mult[a, b] z[a-1, b-1], y = W - mean I
    for b in range(N):
        out[0, b] = W[0, b]
    out[0, 0] -= mean
    for a in range(1, N):
        out[a, 0] = W[a, 0]
        for b in range(1, a):
            out[a, b] = W[a, b] - mult[a, b] * out[a - 1, b - 1]
        out[a, a] = (W[a, a] - mean) - mult[a, a] * out[a - 1, a - 1]
        for b in range(a + 1, N):
            out[a, b] = W[a, b] - mult[a, b] * out[a - 1, b - 1]
    # backward sweep: x[a, b] = z[a, b] inv_piv[a, b] - mult[a+1, b+1] x[a+1, b+1]
    for b in range(N):
        out[N - 1, b] *= inv_piv[N - 1, b]
    for a in range(N - 2, -1, -1):
        for b in range(N - 1):
            out[a, b] = out[a, b] * inv_piv[a, b] - mult[a + 1, b + 1] * out[a + 1, b + 1]
        out[a, N - 1] *= inv_piv[a, N - 1]
    # make the main diagonal traceless (removes the arbitrary kernel component)
    tr = 0.0j
    for a in range(N):
        tr += out[a, a]
    mean = tr / N
    for a in range(N):
        out[a, a] -= mean


@numba.njit(cache=True)
def euler_field(W, out, inv_piv, mult, inv_hbar, shift):  # type: ignore[no-untyped-def]
    r"""Zeitlin's ``B(W) = P / hbar + diag(shift)`` with :math:`\Delta_N P = W` (``P``
    traceless), for one ``(N, N)`` complex matrix: the ``f(W, out, *args)`` of the Euler
    model's :class:`~isoflow.CompiledB` kernel.

    ``W`` may have a trace (the IsoMP stage lies in ``u(N)``); it is ignored. ``shift`` is
    the diagonal of the constant part of ``B`` (zero on a non-rotating sphere, see
    :func:`isoflow.models.euler_sphere`).
    """
    poisson_solve(W, out, inv_piv, mult)
    N = W.shape[0]
    for a in range(N):
        for b in range(N):
            out[a, b] *= inv_hbar
        out[a, a] += shift[a]


@numba.njit(cache=True)
def mhd_field(W, out, inv_piv, mult, diag, gamma, inv_hbar, shift):  # type: ignore[no-untyped-def]
    r"""Zeitlin's MHD ``B = (P / hbar + diag(shift), J / hbar)`` on the pair ``W = (Theta, Q)``,
    ``(2, N, N)``: :math:`\Delta_N P = Q` (:func:`euler_field` on the second field, the same
    function and arithmetic as the Euler model) and the current :math:`J = \Delta_N\Theta`
    (:func:`laplacian_apply`; the trace of a stage's :math:`\Theta` is in the kernel of
    :math:`\Delta_N` and drops out). The ``f(W, out, *args)`` of
    :func:`isoflow.models.mhd_sphere`'s :class:`~isoflow.CompiledB` kernel.
    """
    euler_field(W[1], out[0], inv_piv, mult, inv_hbar, shift)
    laplacian_apply(W[0], out[1], diag, gamma)
    N = W.shape[1]
    for a in range(N):
        for b in range(N):
            out[1, a, b] *= inv_hbar


@numba.njit(cache=True)
def laplacian_apply_batch(W, out, diag, gamma):  # type: ignore[no-untyped-def]
    """:func:`laplacian_apply` on every member of stacked ``(M, N, N)`` matrices."""
    for k in range(W.shape[0]):
        laplacian_apply(W[k], out[k], diag, gamma)


@numba.njit(cache=True)
def poisson_solve_batch(W, out, inv_piv, mult):  # type: ignore[no-untyped-def]
    """:func:`poisson_solve` on every member of stacked ``(M, N, N)`` matrices."""
    for k in range(W.shape[0]):
        poisson_solve(W[k], out[k], inv_piv, mult)
