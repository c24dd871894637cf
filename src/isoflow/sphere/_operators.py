r"""The Hoppe–Yau Laplacian :math:`\Delta_N` on ``u(N)``: coefficients, application, inverse."""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._errors import ParameterError, ShapeError

__all__ = [
    "LaplacianCoefficients",
    "as_matrices",
    "check_N",
    "hbar",
    "laplacian",
    "laplacian_block",
    "laplacian_coefficients",
    "solve_poisson",
    "spin_matrices",
]

Array = NDArray[Any]


def check_N(N: Any, what: str = "N", minimum: int = 2) -> int:
    """Validate a matrix size ``N >= minimum`` (an integer, not a bool)."""
    if isinstance(N, bool) or not isinstance(N, (int, np.integer)):
        raise ParameterError(f"{what} must be an integer, got {N!r}")
    if N < minimum:
        raise ParameterError(f"{what} must be >= {minimum}, got {N}")
    return int(N)


def hbar(N: int) -> float:
    r"""Zeitlin's deformation parameter :math:`\hbar = 2/\sqrt{N^2 - 1}`.

    With it the spin matrices scaled by :math:`\hbar` are the quantized Cartesian coordinates
    of the unit sphere, :math:`X_a = \hbar J_a`, :math:`X_1^2 + X_2^2 + X_3^2 = I`, and
    :math:`[X_a, X_b] = i\hbar\,\varepsilon_{abc} X_c` is the quantized Poisson bracket
    :math:`\{x_a, x_b\} = \varepsilon_{abc} x_c`.
    """
    N = check_N(N)
    return 2.0 / float(np.sqrt(N * N - 1.0))


def spin_matrices(N: int) -> tuple[Array, Array, Array]:
    r"""The skew-Hermitian spin generators :math:`S_a = i J_a` of the irreducible
    ``N``-dimensional representation (dense, ``O(N^2)``, for references and tests).

    Basis :math:`|m\rangle`, :math:`m = -s, \dots, s`, :math:`s = (N-1)/2`, in that order
    (row/column ``a`` is :math:`m_a = a - s`). :math:`J_3 = \operatorname{diag}(m_a)`,
    :math:`J_+ = J_1 + iJ_2` has :math:`(J_+)_{a+1,a} = \sqrt{(a+1)(N-a-1)}`, so that
    :math:`[J_1, J_2] = i J_3` (cyclic) and :math:`\sum_a J_a^2 = s(s+1) I`.

    Returns
    -------
    S1, S2, S3 : ndarray, shape (N, N), complex128
        :math:`S_a = i J_a`; the Laplacian is :math:`\Delta_N W = \sum_a [S_a, [S_a, W]]`.
    """
    N = check_N(N, minimum=1)
    a = np.arange(N - 1)
    Jp = np.zeros((N, N), dtype=np.complex128)
    Jp[a + 1, a] = np.sqrt((a + 1.0) * (N - a - 1.0))
    Jm = Jp.conj().T
    J1 = 0.5 * (Jp + Jm)
    J2 = -0.5j * (Jp - Jm)
    J3 = np.diag(np.arange(N) - 0.5 * (N - 1)).astype(np.complex128)
    return 1j * J1, 1j * J2, 1j * J3


def laplacian_block(N: int, m: int) -> tuple[Array, Array]:
    r"""The symmetric tridiagonal block of :math:`\Delta_N` on diagonal ``m``.

    Diagonal ``m >= 0`` holds the entries :math:`W_{i+m,\,i}`, ``i = 0..N-m-1`` (and, with the
    same block, the entries :math:`W_{i,\,i+m}` of diagonal ``-m``). From
    :math:`\Delta_N W = \sum_a [S_a,[S_a,W]]`:

    .. math::

        (\Delta_N W)_{ab} = -2\big(s(s+1) - m_a m_b\big) W_{ab}
            + c_{a-1} c_{b-1} W_{a-1,b-1} + c_a c_b W_{a+1,b+1},
        \qquad c_a = \sqrt{(a+1)(N-a-1)},

    which on diagonal ``m`` is the tridiagonal matrix with

    .. math::

        d_i = 2i(i+m) - (N-1)(2i+1+m), \qquad
        e_i = \sqrt{(i+m)(N-i-m)\, i\, (N-i)} \quad (\text{coupling of } i-1 \text{ and } i).

    Its eigenvalues are :math:`-l(l+1)`, :math:`l = |m|, \dots, N-1`.

    Returns
    -------
    d : ndarray, shape (N - |m|,)
    e : ndarray, shape (N - |m| - 1,)
        ``e[k]`` couples entries ``k`` and ``k + 1``.
    """
    N = check_N(N, minimum=1)
    if isinstance(m, bool) or not isinstance(m, (int, np.integer)) or not -N < m < N:
        raise ParameterError(f"laplacian_block: m must be an integer with |m| < N = {N}, got {m!r}")
    m = abs(int(m))
    i = np.arange(N - m, dtype=np.float64)
    d = 2.0 * i * (i + m) - (N - 1.0) * (2.0 * i + 1.0 + m)
    j = i[1:]
    e = np.sqrt((j + m) * (N - j - m) * j * (N - j))
    return d, e


@dataclass(frozen=True, eq=False)
class LaplacianCoefficients:
    r"""Precomputed coefficients of :math:`\Delta_N` and of its inverse on ``su(N)``.

    All arrays are read-only and ``O(N^2)``; pass them to the compiled kernels of
    :mod:`isoflow.sphere.compiled`.

    Attributes
    ----------
    N : int
    diag : ndarray, shape (N, N)
        :math:`2ab - (N-1)(a+b+1)`: the coefficient of :math:`W_{ab}` in
        :math:`(\Delta_N W)_{ab}`.
    gamma : ndarray, shape (N + 1,)
        :math:`\gamma_a = \sqrt{a(N-a)}`; :math:`W_{ab}` couples to :math:`W_{a-1,b-1}` with
        :math:`\gamma_a\gamma_b`.
    inv_piv, mult : ndarray, shape (N, N)
        The :math:`LDL^T` factorization of every diagonal's block, in position:
        ``mult[a, b]`` is the multiplier :math:`\ell` between entries ``(a-1, b-1)`` and
        ``(a, b)`` (0 on the first row and column), ``inv_piv[a, b] = 1/delta`` the inverse
        pivot of entry ``(a, b)``; ``inv_piv[N-1, N-1] = 0`` (the main diagonal's block is
        singular, its kernel the identity; see :func:`~isoflow.sphere.compiled.poisson_solve`).
    """

    N: int
    diag: Array
    gamma: Array
    inv_piv: Array
    mult: Array


@functools.lru_cache(maxsize=8)
def laplacian_coefficients(N: int) -> LaplacianCoefficients:
    r"""The coefficients of :math:`\Delta_N` and its factorization for size ``N`` (cached).

    ``O(N^2)`` work and storage: four real ``(N, N)`` arrays (``diag``, ``inv_piv``,
    ``mult`` and a temporary), computed by sweeping all diagonals at once, row by row.
    """
    N = check_N(N)
    a = np.arange(N, dtype=np.float64)
    diag = 2.0 * a[:, None] * a[None, :] - (N - 1.0) * (a[:, None] + a[None, :] + 1.0)
    gamma = np.sqrt(np.arange(N + 1.0) * (N - np.arange(N + 1.0)))
    coupling = gamma[:N, None] * gamma[None, :N]  # couples (a, b) with (a-1, b-1)
    piv = np.empty((N, N))
    mult = np.zeros((N, N))
    piv[0, :] = diag[0, :]
    piv[:, 0] = diag[:, 0]
    for r in range(1, N):  # row r, columns 1..N-1: the i-th step of every diagonal's LDL^T
        mult[r, 1:] = coupling[r, 1:] / piv[r - 1, :-1]
        piv[r, 1:] = diag[r, 1:] - mult[r, 1:] * coupling[r, 1:]
    with np.errstate(divide="ignore"):  # the last pivot below may round to exactly 0
        inv_piv = 1.0 / piv
    # The main diagonal's block has the identity in its kernel: its last pivot is zero up to
    # rounding and is not used (the solve pins that entry and removes the mean afterwards).
    inv_piv[N - 1, N - 1] = 0.0
    for arr in (diag, gamma, inv_piv, mult):
        arr.setflags(write=False)
    return LaplacianCoefficients(N=N, diag=diag, gamma=gamma, inv_piv=inv_piv, mult=mult)


def as_matrices(W: ArrayLike, what: str) -> tuple[Array, tuple[int, ...], int]:
    """``W`` (``(*batch, N, N)``) as a contiguous complex ``(M, N, N)`` stack, the batch shape
    and ``N``.

    Raises
    ------
    ShapeError
        Not a stack of square numeric matrices, or ``N`` out of range (``what`` names the
        argument).
    """
    Wa = np.asarray(W)
    if Wa.ndim < 2 or Wa.shape[-1] != Wa.shape[-2]:
        raise ShapeError(f"{what}: expected matrices of shape (*batch, N, N), got {Wa.shape}")
    if Wa.dtype.kind not in "biufc":
        raise ShapeError(f"{what}: expected numeric matrices, got dtype {Wa.dtype}")
    N = Wa.shape[-1]
    check_N(N, f"{what}: the matrix size N")
    flat = np.ascontiguousarray(Wa.reshape(-1, N, N), dtype=np.complex128)
    return flat, Wa.shape[:-2], N


def laplacian(W: ArrayLike) -> Array:
    r""":math:`\Delta_N W = \sum_{a=1}^3 [S_a, [S_a, W]]` (Hoppe–Yau), ``O(N^2)`` per matrix.

    Parameters
    ----------
    W : array_like, shape (*batch, N, N)
        Any complex matrices (the operator is real-linear and maps ``u(N)``, ``su(N)`` to
        themselves).

    Returns
    -------
    ndarray, shape (*batch, N, N), complex128
    """
    from .compiled import laplacian_apply_batch

    flat, batch, N = as_matrices(W, "laplacian")
    c = laplacian_coefficients(N)
    out = np.empty_like(flat)
    laplacian_apply_batch(flat, out, c.diag, c.gamma)
    return out.reshape(*batch, N, N)


def solve_poisson(W: ArrayLike) -> Array:
    r"""The stream matrix: the traceless ``P`` with :math:`\Delta_N P = W - \frac{\operatorname{Tr}
    W}{N} I`, ``O(N^2)`` per matrix.

    The trace part of ``W`` (the kernel of :math:`\Delta_N`, the ``l = 0`` mode) is removed;
    on ``su(N)`` this is the inverse of :math:`\Delta_N`.

    Parameters
    ----------
    W : array_like, shape (*batch, N, N)

    Returns
    -------
    ndarray, shape (*batch, N, N), complex128
    """
    from .compiled import poisson_solve_batch

    flat, batch, N = as_matrices(W, "solve_poisson")
    c = laplacian_coefficients(N)
    out = np.empty_like(flat)
    poisson_solve_batch(flat, out, c.inv_piv, c.mult)
    return out.reshape(*batch, N, N)
