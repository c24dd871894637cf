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

from typing import Any, NamedTuple

import numba
import numpy as np
from numpy.typing import NDArray

from .._compiled.stages.split import provide_flow

#: The symmetric products may fuse multiplies and adds, never reassociate (they move states).
_FM = {"nsz", "contract"}

__all__ = [
    "SphereFlow",
    "dissipate",
    "euler_double_bracket_field",
    "euler_field",
    "helmholtz_solve",
    "helmholtz_solve_batch",
    "laplacian_apply",
    "laplacian_apply_batch",
    "mhd_field",
    "poisson_solve",
    "poisson_solve_batch",
    "qg_field",
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
    shift = np.full(N, tr / N)
    _sweeps(W, shift, out, inv_piv, mult)
    # make the main diagonal traceless (removes the arbitrary kernel component)
    tr = 0.0j
    for a in range(N):
        tr += out[a, a]
    mean = tr / N
    for a in range(N):
        out[a, a] -= mean


@numba.njit(cache=True, inline="always")
def _sweeps(W, shift, out, inv_piv, mult):  # type: ignore[no-untyped-def]
    """``out`` solving every diagonal's tridiagonal system for the right-hand side ``W`` minus
    ``diag(shift)`` (the factorization in position: forward then backward sweep, row by row,
    all diagonals at once)."""
    N = W.shape[0]
    # forward sweep, row by row: z[a, b] = y[a, b] - mult[a, b] z[a-1, b-1], y = W - diag(shift)
    for b in range(N):
        out[0, b] = W[0, b]
    out[0, 0] -= shift[0]
    for a in range(1, N):
        out[a, 0] = W[a, 0]
        for b in range(1, a):
            out[a, b] = W[a, b] - mult[a, b] * out[a - 1, b - 1]
        out[a, a] = (W[a, a] - shift[a]) - mult[a, a] * out[a - 1, a - 1]
        for b in range(a + 1, N):
            out[a, b] = W[a, b] - mult[a, b] * out[a - 1, b - 1]
    # backward sweep: x[a, b] = z[a, b] inv_piv[a, b] - mult[a+1, b+1] x[a+1, b+1]
    for b in range(N):
        out[N - 1, b] *= inv_piv[N - 1, b]
    for a in range(N - 2, -1, -1):
        for b in range(N - 1):
            out[a, b] = out[a, b] * inv_piv[a, b] - mult[a + 1, b + 1] * out[a + 1, b + 1]
        out[a, N - 1] *= inv_piv[a, N - 1]


@numba.njit(cache=True)
def helmholtz_solve(W, out, inv_piv, mult, shift):  # type: ignore[no-untyped-def]
    r"""``out = A^{-1}(W - \mathrm{diag}(\text{shift}))`` for an operator ``A`` with
    :math:`\Delta_N`'s structure whose every diagonal block is definite (the quasi-geostrophic
    :math:`\Delta_N - \kappa^2 - F\,\tfrac12\{Z^2, \cdot\}`; ``inv_piv``, ``mult`` from
    ``isoflow.sphere._operators.factor_diagonals``). ``O(N^2)``: two sweeps, as
    :func:`poisson_solve`, without its trace handling (the trace is part of the solution).

    Parameters
    ----------
    W : complex128[N, N]
    out : complex128[N, N]
        Written entirely; must not be ``W``.
    inv_piv, mult : float64[N, N]
        The factorization of ``A``.
    shift : complex128[N] or float64[N]
        The diagonal subtracted from ``W`` before the solve.
    """
    _sweeps(W, shift, out, inv_piv, mult)


@numba.njit(cache=True)
def qg_field(W, out, inv_piv, mult, inv_hbar, planetary):  # type: ignore[no-untyped-def]
    r"""The quasi-geostrophic ``B(Q) = \Psi_0/\hbar``: :math:`A\Psi = Q_0 - F` for the traceless
    part :math:`Q_0` of ``Q`` (``planetary`` the diagonal of the planetary vorticity ``F``),
    :math:`\Psi_0` the traceless part of :math:`\Psi` (:func:`helmholtz_solve`): the
    ``f(W, out, *args)`` of :func:`isoflow.models.qg_sphere`'s kernel.

    The model's states have zero mean potential vorticity (a Casimir); the trace IsoMP's stage
    carries (``O(h^2)``) is ignored, as Euler's field ignores it, and the trace of
    :math:`\Psi` (it commutes with everything, but would rescale the Cayley map's step) is
    removed: the step tends to Euler's as ``F, kappa -> 0``.

    Parameters
    ----------
    W : complex128[N, N]
        The potential vorticity ``Q`` (a trace is ignored).
    out : complex128[N, N]
        Written with ``B``; must not be ``W``.
    inv_piv, mult : float64[N, N]
        The factorization of ``A`` (:func:`isoflow.models.qg_operator`).
    inv_hbar : float
        :math:`1/\hbar`.
    planetary : float64[N] or complex128[N]
        The diagonal of the planetary vorticity ``F``.
    """
    N = W.shape[0]
    tr = 0.0j
    for a in range(N):
        tr += W[a, a]
    shift = planetary + tr / N
    _sweeps(W, shift, out, inv_piv, mult)
    tr = 0.0j
    for a in range(N):
        tr += out[a, a]
    mean = tr / N
    for a in range(N):
        out[a, a] -= mean
    for a in range(N):
        for b in range(N):
            out[a, b] *= inv_hbar


@numba.njit(cache=True)
def euler_field(W, out, inv_piv, mult, inv_hbar, shift):  # type: ignore[no-untyped-def]
    r"""Zeitlin's ``B(W) = P / hbar + diag(shift)`` with :math:`\Delta_N P = W` (``P``
    traceless), for one ``(N, N)`` complex matrix: the ``f(W, out, *args)`` of the Euler
    model's :class:`~isoflow.CompiledB` kernel.

    ``W`` may have a trace (the IsoMP stage lies in ``u(N)``); it is ignored. ``shift`` is
    the diagonal of the constant part of ``B`` (zero on a non-rotating sphere, see
    :func:`isoflow.models.euler_sphere`).

    Parameters
    ----------
    W : complex128[N, N]
        The vorticity matrix (or an IsoMP stage).
    out : complex128[N, N]
        Written with ``B``; must not be ``W``.
    inv_piv, mult : float64[N, N]
        The factorization from :func:`isoflow.sphere.laplacian_coefficients`.
    inv_hbar : float
        :math:`1/\hbar`.
    shift : complex128[N]
        The diagonal of the constant part of ``B``.
    """
    poisson_solve(W, out, inv_piv, mult)
    N = W.shape[0]
    for a in range(N):
        for b in range(N):
            out[a, b] *= inv_hbar
        out[a, a] += shift[a]


@numba.njit(cache=True)
def euler_double_bracket_field(W, out, inv_piv, mult, inv_hbar, shift, hbar, alpha):  # type: ignore[no-untyped-def]
    r"""The Euler field with selective decay: :math:`B = \Psi/\hbar - \alpha[\Psi, W]` with the
    relative stream matrix :math:`\Psi = P + \hbar\,\mathrm{diag}(\text{shift})`,
    :math:`\Delta_N P = W` (:func:`euler_field` for ``alpha = 0``).

    :math:`\dot W = [B, W]` then adds :math:`-\alpha[[\Psi, W], W]` to Zeitlin's flow: still
    isospectral (every Casimir kept), while the energy decreases at the rate
    :math:`\frac{4\pi}{N}\alpha\|[\Psi, W]\|_F^2` (``docs/theory/forced.rst``). Two matrix
    products per evaluation (BLAS).

    Parameters
    ----------
    W : complex128[N, N]
        The vorticity matrix.
    out : complex128[N, N]
        Written with ``B``; must not be ``W``.
    inv_piv, mult : float64[N, N]
        The factorization from :func:`isoflow.sphere.laplacian_coefficients`.
    inv_hbar : float
        :math:`1/\hbar`.
    shift : complex128[N]
        As in :func:`euler_field` (scaled by ``hbar`` into :math:`\Psi`).
    hbar : float
        :math:`\hbar`.
    alpha : float
        The selective-decay coefficient :math:`\alpha` (0: Euler's field).
    """
    poisson_solve(W, out, inv_piv, mult)
    N = W.shape[0]
    for a in range(N):
        out[a, a] += hbar * shift[a]
    C = np.dot(out, W) - np.dot(W, out)
    for a in range(N):
        for b in range(N):
            out[a, b] = out[a, b] * inv_hbar - alpha * C[a, b]


@numba.njit(cache=True)
def mhd_field(W, out, inv_piv, mult, diag, gamma, inv_hbar, shift):  # type: ignore[no-untyped-def]
    r"""Zeitlin's MHD ``B = (P / hbar + diag(shift), J / hbar)`` on the pair ``W = (Theta, Q)``,
    ``(2, N, N)``: :math:`\Delta_N P = Q` (:func:`euler_field` on the second field, the same
    function and arithmetic as the Euler model) and the current :math:`J = \Delta_N\Theta`
    (:func:`laplacian_apply`; the trace of a stage's :math:`\Theta` is in the kernel of
    :math:`\Delta_N` and drops out). The ``f(W, out, *args)`` of
    :func:`isoflow.models.mhd_sphere`'s :class:`~isoflow.CompiledB` kernel.

    Parameters
    ----------
    W : complex128[2, N, N]
        The pair ``(Theta, Q)``.
    out : complex128[2, N, N]
        Written with ``B``; must not be ``W``.
    inv_piv, mult : float64[N, N]
        The factorization from :func:`isoflow.sphere.laplacian_coefficients`.
    diag : float64[N, N]
        The diagonal coefficients of :math:`\Delta_N` (:func:`laplacian_apply`).
    gamma : float64[N + 1]
        The off-diagonal coefficients :math:`\gamma_a` (:func:`laplacian_apply`).
    inv_hbar : float
        :math:`1/\hbar`.
    shift : complex128[N]
        The diagonal of the constant part of ``B``'s first field (:func:`euler_field`).
    """
    euler_field(W[1], out[0], inv_piv, mult, inv_hbar, shift)
    laplacian_apply(W[0], out[1], diag, gamma)
    N = W.shape[1]
    for a in range(N):
        for b in range(N):
            out[1, a, b] *= inv_hbar


@numba.njit(cache=True)
def laplacian_apply_batch(W, out, diag, gamma):  # type: ignore[no-untyped-def]
    """:func:`laplacian_apply` on every member of stacked ``(M, N, N)`` matrices.

    Parameters
    ----------
    W, out : complex128[M, N, N]
        The matrices and the results (``out`` must not be ``W``).
    diag, gamma
        As in :func:`laplacian_apply`.
    """
    for k in range(W.shape[0]):
        laplacian_apply(W[k], out[k], diag, gamma)


@numba.njit(cache=True)
def helmholtz_solve_batch(W, out, inv_piv, mult, shift):  # type: ignore[no-untyped-def]
    """:func:`helmholtz_solve` on every member of stacked ``(M, N, N)`` matrices.

    Parameters
    ----------
    W, out : complex128[M, N, N]
        The right-hand sides and the solutions (``out`` must not be ``W``).
    inv_piv, mult, shift
        As in :func:`helmholtz_solve`, the same for every member.
    """
    for k in range(W.shape[0]):
        helmholtz_solve(W[k], out[k], inv_piv, mult, shift)


@numba.njit(cache=True)
def poisson_solve_batch(W, out, inv_piv, mult):  # type: ignore[no-untyped-def]
    """:func:`poisson_solve` on every member of stacked ``(M, N, N)`` matrices.

    Parameters
    ----------
    W, out : complex128[M, N, N]
        The right-hand sides and the solutions (``out`` must not be ``W``).
    inv_piv, mult
        As in :func:`poisson_solve`.
    """
    for k in range(W.shape[0]):
        poisson_solve(W[k], out[k], inv_piv, mult)


# ---- the exact flow of the dissipation, diagonal by diagonal ----------------------------------


class SphereFlow(NamedTuple):
    """The per-diagonal flow of :class:`isoflow.sphere.SphereDissipation` for the half steps of
    a run: ``data[j]`` the upper triangles of every diagonal's even and odd folded matrices for
    half step ``j``, at the offsets ``offe[m]``, ``offo[m]`` of diagonal ``m``."""

    N: int
    data: NDArray[Any]
    offe: NDArray[np.int64]
    offo: NDArray[np.int64]


@numba.njit(cache=True, fastmath=_FM)
def _symmetric_product(P, off, k, xr, xi, yr, yi):  # type: ignore[no-untyped-def]
    """``y = M x`` for the symmetric ``k x k`` matrix ``M`` stored as its upper triangle, row
    by row, at ``P[off:]``, and a complex ``x`` given by its real and imaginary parts.

    The rows are taken in pairs ``(i, i + 1)``. Their parts right of the ``2 x 2`` diagonal
    block serve twice while in the L1 cache: as columns, ``y_j += M_{i,j} x_i + M_{i+1,j}
    x_{i+1}`` (``j >= i + 2``: one load and store of ``y_j`` for two entries, a loop that
    vectorizes without reassociation), and as rows, eight running inner products (real and
    imaginary parts of the two rows, even and odd ``j`` apart) that share each load of ``x_j``.
    A last odd row is its diagonal entry. Measured at ``N = 1024``, the matrices streamed from
    memory as a half step does: 68 ms for every diagonal's products against 128 for one row at
    a time and 90 for four rows at a time (which is faster only in cache: 0.50 ns a stored
    entry at ``k = 512`` against 0.53). No reassociation: the result moves the state, and with
    ``reassoc`` its rounding could depend on how LLVM compiled the loop in a given process (a
    run and its resume would then differ).
    """
    for i in range(k):
        yr[i] = 0.0
        yi[i] = 0.0
    o0 = off
    i = 0
    while i + 1 < k:
        o1 = o0 + k - i  # row i + 1 of the triangle starts at o1 (its diagonal entry)
        p0 = P[o0 + 2 : o0 + k - i]  # M[i, i + 2 : k]
        p1 = P[o1 + 1 : o1 + k - i - 1]  # M[i + 1, i + 2 : k]
        cr = yr[i + 2 : k]
        ci = yi[i + 2 : k]
        ur = xr[i + 2 : k]
        ui = xi[i + 2 : k]
        x0r, x1r = xr[i], xr[i + 1]
        x0i, x1i = xi[i], xi[i + 1]
        n = p0.shape[0]
        for t in range(n):
            cr[t] += p0[t] * x0r + p1[t] * x1r
            ci[t] += p0[t] * x0i + p1[t] * x1i
        r0 = s0 = r1 = s1 = 0.0  # even t
        q0 = v0 = q1 = v1 = 0.0  # odd t
        for c in range(n // 2):
            t = 2 * c
            r0 += p0[t] * ur[t]
            s0 += p0[t] * ui[t]
            r1 += p1[t] * ur[t]
            s1 += p1[t] * ui[t]
            q0 += p0[t + 1] * ur[t + 1]
            v0 += p0[t + 1] * ui[t + 1]
            q1 += p1[t + 1] * ur[t + 1]
            v1 += p1[t + 1] * ui[t + 1]
        if n % 2:
            t = n - 1
            r0 += p0[t] * ur[t]
            s0 += p0[t] * ui[t]
            r1 += p1[t] * ur[t]
            s1 += p1[t] * ui[t]
        d0, m01, d1 = P[o0], P[o0 + 1], P[o1]
        yr[i] += (d0 * x0r + m01 * x1r) + (r0 + q0)
        yi[i] += (d0 * x0i + m01 * x1i) + (s0 + v0)
        yr[i + 1] += (m01 * x0r + d1 * x1r) + (r1 + q1)
        yi[i + 1] += (m01 * x0i + d1 * x1i) + (s1 + v1)
        o0 = o1 + k - i - 1
        i += 2
    if i < k:  # the last row of an odd k: its diagonal entry
        yr[i] += P[o0] * xr[i]
        yi[i] += P[o0] * xi[i]


#: Side of the square tiles in which :func:`dissipate` moves the matrix to and from its
#: diagonals (a tile of ``W`` and the window of the diagonal buffers it maps to stay in cache).
_TILE = 32


@numba.njit(cache=True)
def _gather_diagonals(W, Dr, Di):  # type: ignore[no-untyped-def]
    """``Dr[m, p] + i Di[m, p] = W[p + m, p]`` for the lower triangle (``m >= 0``), tile by tile:
    the rows of a tile are read in order and its ``2T x T`` window of the buffers is hot."""
    N = W.shape[0]
    for a0 in range(0, N, _TILE):
        a1 = min(a0 + _TILE, N)
        for b0 in range(0, a1, _TILE):
            for a in range(a0, a1):
                for b in range(b0, min(b0 + _TILE, a + 1)):
                    x = W[a, b]
                    Dr[a - b, b] = x.real
                    Di[a - b, b] = x.imag


@numba.njit(cache=True)
def _scatter_diagonals(W, Dr, Di):  # type: ignore[no-untyped-def]
    """The inverse of :func:`_gather_diagonals`, and the mirror ``W[p, p + m] =
    -conj(W[p + m, p])`` of every diagonal ``m > 0`` (skew-Hermitian), tile by tile."""
    N = W.shape[0]
    for a0 in range(0, N, _TILE):
        a1 = min(a0 + _TILE, N)
        for b0 in range(0, a1, _TILE):
            for a in range(a0, a1):
                for b in range(b0, min(b0 + _TILE, a + 1)):
                    W[a, b] = complex(Dr[a - b, b], Di[a - b, b])
            for b in range(b0, min(b0 + _TILE, a1)):  # the mirror tile, row by row
                for a in range(max(a0, b + 1), a1):
                    W[b, a] = complex(-Dr[a - b, b], Di[a - b, b])


@numba.njit(cache=True)
def dissipate(W, data, offe, offo):  # type: ignore[no-untyped-def]
    r"""``W = f(-\Delta_N) W`` in place for one ``(N, N)`` skew-Hermitian matrix, with the
    folded matrices of :class:`isoflow.sphere.SphereDissipation` (``data``: one half step's).

    The lower triangle is first moved to its diagonals (:func:`_gather_diagonals`, in tiles:
    read diagonal by diagonal, the matrix costs a cache miss per entry). On diagonal ``m``
    (``n = N - m`` entries): sums :math:`a_i = x_i + x_{n-1-i}` and differences
    :math:`b_i = x_i - x_{n-1-i}` (real and imaginary parts apart), their products with the
    even and odd matrices, back; the diagonals then return to the matrix with their mirrors
    :math:`W_{i, i+m} = -\overline{W_{i+m, i}}` (exactly what the product would give).

    Parameters
    ----------
    W : complex128[N, N]
        The matrix, overwritten with the result.
    data : float64[:]
        The upper triangles of every diagonal's even and odd folded matrices, one after the
        other (row by row).
    offe, offo : int64[N]
        Where diagonal ``m``'s even and odd matrix start in ``data``.
    """
    N = W.shape[0]
    half = (N + 1) // 2
    Dr = np.empty((N, N))
    Di = np.empty((N, N))
    _gather_diagonals(W, Dr, Di)
    ar = np.empty(half)
    ai = np.empty(half)
    br = np.empty(half)
    bi = np.empty(half)
    yar = np.empty(half)
    yai = np.empty(half)
    ybr = np.empty(half)
    ybi = np.empty(half)
    for m in range(N):
        n = N - m
        h2 = n // 2
        odd = n - 2 * h2
        xr = Dr[m]
        xi = Di[m]
        for p in range(h2):
            q = n - 1 - p
            ar[p] = xr[p] + xr[q]
            ai[p] = xi[p] + xi[q]
            br[p] = xr[p] - xr[q]
            bi[p] = xi[p] - xi[q]
        if odd:
            ar[h2] = xr[h2]
            ai[h2] = xi[h2]
        _symmetric_product(data, offe[m], h2 + odd, ar, ai, yar, yai)
        _symmetric_product(data, offo[m], h2, br, bi, ybr, ybi)
        for p in range(h2):
            q = n - 1 - p
            xr[p] = yar[p] + ybr[p]
            xi[p] = yai[p] + ybi[p]
            xr[q] = yar[p] - ybr[p]
            xi[q] = yai[p] - ybi[p]
        if odd:
            xr[h2] = yar[h2]
            xi[h2] = yai[h2]
    _scatter_diagonals(W, Dr, Di)


class SplitSphereFlow(NamedTuple):
    """The split stage's flat parameters with a :class:`SphereFlow`
    (:class:`isoflow._compiled.stages.split.SplitNoFlow` says why flat)."""

    taus: NDArray[Any]
    indptr: NDArray[np.int64]
    idx: NDArray[np.int64]
    val: NDArray[Any]
    amp: NDArray[np.int64]
    N: int
    data: NDArray[Any]
    offe: NDArray[np.int64]
    offo: NDArray[np.int64]


@provide_flow(SphereFlow, SplitSphereFlow)
@numba.njit(cache=True)
def _sphere_flow(flow, W, j):  # type: ignore[no-untyped-def]
    N = flow.N
    dissipate(W.reshape((N, N)), flow.data[j], flow.offe, flow.offo)
