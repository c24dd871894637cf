r"""Quantized spherical harmonics :math:`T_{lm}` and the map ``su(N)`` <-> coefficients."""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._errors import DtypeError, NonFiniteError, ParameterError, ShapeError
from ._operators import check_N, laplacian_block

__all__ = [
    "basis_matrix",
    "coefficient_array",
    "coefficient_count",
    "degree_order",
    "diagonal_bases",
    "from_coefficients",
    "lm_index",
    "lmax_of",
    "to_coefficients",
]

Array = NDArray[Any]


def coefficient_count(lmax: int) -> int:
    """Number of real coefficients with ``1 <= l <= lmax``: :math:`(l_{max}+1)^2 - 1`.

    For ``lmax = N - 1`` this is ``N^2 - 1``, the real dimension of ``su(N)``.
    """
    lmax = check_N(lmax, "lmax", minimum=0)
    return (lmax + 1) ** 2 - 1


def lm_index(l: ArrayLike, m: ArrayLike) -> Any:
    r"""Flat index of the coefficient :math:`\omega_{lm}`: :math:`l^2 - 1 + l + m`.

    Coefficients are stored degree by degree, ``l = 1, 2, ...``, and within a degree by order
    ``m = -l, ..., l``: ``(1,-1), (1,0), (1,1), (2,-2), ...``.
    """
    la, ma = np.asarray(l), np.asarray(m)
    if np.any(la < 1) or np.any(np.abs(ma) > la):
        raise ParameterError(f"lm_index: need l >= 1 and |m| <= l, got l={l!r}, m={m!r}")
    out = la * la - 1 + la + ma
    return int(out) if out.ndim == 0 else out


def degree_order(lmax: int) -> tuple[Array, Array]:
    """The degrees ``l`` and orders ``m`` of the flat coefficient layout up to ``lmax``."""
    lmax = check_N(lmax, "lmax", minimum=0)
    degrees = np.arange(1, lmax + 1, dtype=np.int64)
    ls = np.repeat(degrees, 2 * degrees + 1)
    ms = np.arange(ls.size, dtype=np.int64) + 1 - ls * ls - ls  # index = l^2 - 1 + l + m
    return ls, ms


def lmax_of(ncoef: int, what: str) -> int:
    """The degree ``lmax`` of ``ncoef = (lmax+1)^2 - 1`` coefficients (``l = 1..lmax``).

    Raises
    ------
    ShapeError
        ``ncoef`` is not such a count (``what`` names the argument).
    """
    lmax = math.isqrt(max(ncoef + 1, 0)) - 1
    if lmax < 1 or (lmax + 1) ** 2 - 1 != ncoef:
        raise ShapeError(
            f"{what}: the last axis must hold (lmax+1)^2 - 1 coefficients (l = 1..lmax, "
            f"m = -l..l), e.g. 3, 8, 15, ...; got {ncoef}"
        )
    return lmax


def _raw_eigenvectors(N: int, m: int) -> Array:
    """Unit eigenvectors of diagonal ``m``'s block, columns ordered by ``l = m..N-1``."""
    from scipy.linalg import eigh_tridiagonal

    d, e = laplacian_block(N, m)
    if d.size == 1:
        return np.ones((1, 1))
    _, V = eigh_tridiagonal(d, e)  # ascending eigenvalues: l = N-1 first
    return np.ascontiguousarray(V[:, ::-1])


def diagonal_bases(N: int, mmax: int | None = None) -> Iterator[tuple[int, Array]]:
    r"""The unit eigenvectors of :math:`\Delta_N` on each diagonal ``m = 0..mmax``, signed so
    that they are the quantized spherical harmonics (Condon–Shortley phases).

    Yields ``(m, V)`` with ``V`` of shape ``(N - m, N - m)``: column ``j`` is the entries
    :math:`(T_{lm})_{i+m,\,i}`, ``i = 0..N-m-1``, of :math:`T_{lm}/\|T_{lm}\|_F` for
    ``l = m + j``. ``O(N^2)`` memory at a time (one diagonal and its predecessor); ``O(N^3)``
    time over all ``m``, as ``scipy.linalg.eigh_tridiagonal`` is called once per diagonal.

    Signs (the phase convention of :math:`Y_{lm}`): the entry of :math:`T_{l0}` nearest the
    north pole, :math:`(T_{l0})_{N-1,N-1}`, is positive (as :math:`Y_{l0}(\text{north}) > 0`);
    and, as the ladder relation :math:`L_+ Y_{lm} = \sqrt{(l-m)(l+m+1)}\,Y_{l,m+1}` with
    :math:`L_+ = L_1 + iL_2` and the angular momentum :math:`L_a \leftrightarrow
    \operatorname{ad}_{J_a}`,

    .. math::

        [J_+, T_{lm}] = \sqrt{(l-m)(l+m+1)}\; T_{l,m+1}.

    The sign of each column on diagonal ``m + 1`` is fixed by the sign of its inner product
    with :math:`[J_+, T_{lm}]` (computed in ``O(N)``: ``J_+`` maps diagonal ``m`` to diagonal
    ``m + 1`` bidiagonally); that inner product has magnitude :math:`\sqrt{(l-m)(l+m+1)}
    \ge 1`, so the choice is robust where entries near the poles are tiny.
    """
    N = check_N(N, minimum=1)
    mmax = N - 1 if mmax is None else int(mmax)
    if not 0 <= mmax < N:
        raise ParameterError(f"diagonal_bases: need 0 <= mmax < N = {N}, got {mmax}")
    V = _raw_eigenvectors(N, 0)
    V *= np.where(V[-1, :] < 0, -1.0, 1.0)[None, :]
    yield 0, V
    a = np.arange(N, dtype=np.float64)
    c = np.sqrt((a + 1.0) * (N - a - 1.0))  # (J_+)_{a+1, a}
    for m in range(1, mmax + 1):
        n = N - m
        # [J_+, T]_{b+m, b} = c_{b+m-1} T_{b+m-1, b} - c_b T_{b+m, b+1}, T on diagonal m-1
        b = np.arange(n)
        U = c[b + m - 1, None] * V[b, :] - c[b, None] * V[b + 1, :]  # (n, N-m+1)
        Vm = _raw_eigenvectors(N, m)
        # column j of Vm is l = m + j, column j + 1 of V (diagonal m-1) the same l
        dots = np.einsum("ij,ij->j", Vm, U[:, 1:])
        Vm *= np.where(dots < 0, -1.0, 1.0)[None, :]
        V = Vm
        yield m, V


#: The bases of :func:`to_coefficients` and :func:`from_coefficients` are kept for the last
#: ``N`` whose bases (:math:`\approx N^3/3` doubles) fit in this many bytes: up to ``N = 512``
#: (359 MB). Computing them takes ``N`` tridiagonal eigensolves (0.36 s at ``N = 256``, 2.2 s at
#: 512, about 20 s at 1024 on one core), which the spectra and budgets of a forced run would
#: otherwise repeat for every chunk of saved states. Set it to 0 to keep nothing.
BASES_CACHE_BYTES = 400 * 10**6
_bases_kept: list[tuple[int, tuple[Array, ...]]] = []  # at most one entry: (N, bases)


def _bases_bytes(N: int) -> int:
    return 8 * sum((N - m) ** 2 for m in range(N))


def bases(N: int, mmax: int) -> Iterator[tuple[int, Array]]:
    """:func:`diagonal_bases` ``(N, mmax)``, from the kept bases when they fit
    :data:`BASES_CACHE_BYTES` (computed in full once, then read-only), else computed afresh."""
    if _bases_bytes(N) > BASES_CACHE_BYTES:
        yield from diagonal_bases(N, mmax)
        return
    kept = _bases_kept[0] if _bases_kept else None  # one read: another thread may replace it
    if kept is None or kept[0] != N:
        Vs = []
        for _, V in diagonal_bases(N):
            V.setflags(write=False)
            Vs.append(V)
        kept = (N, tuple(Vs))
        _bases_kept[:] = [kept]
    for m in range(mmax + 1):
        yield m, kept[1][m]


def _norm(N: int) -> float:
    """:math:`\\|T_{lm}\\|_F = \\sqrt{N/(4\\pi)}`: orthonormality in the pairing ``(4 pi/N) Tr``."""
    return float(np.sqrt(N / (4.0 * np.pi)))


def basis_matrix(N: int, l: int, m: int, *, kind: str = "real") -> Array:
    r"""One quantized spherical harmonic as a dense ``(N, N)`` matrix.

    Parameters
    ----------
    N : int
    l, m : int
        ``0 <= l <= N - 1``, ``|m| <= l`` (``l = 0`` is :math:`I/\sqrt{4\pi}`).
    kind : {"real", "complex"}
        ``"complex"``: :math:`T_{lm}`, supported on diagonal ``m`` (entries
        :math:`(a+m, a)`; ``m < 0`` above the main diagonal), the counterpart of the complex
        :math:`Y_{lm}` (Condon–Shortley phase), with :math:`T_{l,-m} = (-1)^m T_{lm}^\dagger`.
        ``"real"``: the Hermitian counterpart of the real harmonic (see
        :mod:`isoflow.sphere`): :math:`(T_{l,-m} + (-1)^m T_{lm})/\sqrt2` for ``m > 0``,
        :math:`T_{l0}`, and :math:`i(T_{l,-|m|} - (-1)^m T_{l|m|})/\sqrt2` for ``m < 0``.

    Notes
    -----
    Both are normalized by :math:`\frac{4\pi}{N}\operatorname{Tr}(T^\dagger T) = 1`.
    """
    N = check_N(N, minimum=1)
    if not (0 <= l < N and -l <= m <= l):
        raise ParameterError(f"basis_matrix: need 0 <= l < N = {N} and |m| <= l, got ({l}, {m})")
    if kind not in ("real", "complex"):
        raise ParameterError(f"basis_matrix: kind must be 'real' or 'complex', got {kind!r}")
    mu = abs(m)
    v = None
    for mm, V in diagonal_bases(N, mu):
        if mm == mu:
            v = V[:, l - mu] * _norm(N)
    assert v is not None
    i = np.arange(N - mu)
    lower = np.zeros((N, N), dtype=np.complex128)
    lower[i + mu, i] = v  # T_{l,|m|}
    sign = -1.0 if mu % 2 else 1.0
    if kind == "complex":
        return lower if m >= 0 else sign * lower.conj().T
    if m == 0:
        return lower
    upper = sign * lower.conj().T  # T_{l,-|m|}
    if m > 0:
        return (upper + sign * lower) / np.sqrt(2.0)
    return 1j * (upper - sign * lower) / np.sqrt(2.0)


def coefficient_array(omega: ArrayLike, what: str) -> Array:
    """Coefficients ``omega`` (``(*batch, (lmax+1)^2 - 1)``) as a float64 array.

    Raises
    ------
    DtypeError, ShapeError, NonFiniteError
        Not real numbers, a scalar, or NaN/Inf (``what`` names the argument).
    """
    arr = np.asarray(omega)
    if arr.dtype.kind not in "biuf":
        raise DtypeError(f"{what}: coefficients must be real numbers, got dtype {arr.dtype}")
    arr = arr.astype(np.float64)
    if arr.ndim < 1:
        raise ShapeError(f"{what}: coefficients must have shape (*batch, (lmax+1)^2 - 1)")
    if not np.all(np.isfinite(arr)):
        raise NonFiniteError(f"{what}: coefficients must be finite (found NaN or Inf)")
    return arr


def from_coefficients(omega: ArrayLike, N: int) -> Array:
    r"""The matrix :math:`W = i\sum_{l=1}^{N-1}\sum_{m=-l}^{l} \omega_{lm} T_{lm}` in
    ``su(N)`` of real coefficients :math:`\omega_{lm}` (real harmonics).

    Parameters
    ----------
    omega : array_like, shape (*batch, (lmax+1)^2 - 1)
        Coefficients in the layout of :func:`lm_index`, ``1 <= lmax``; degrees
        ``l > N - 1`` must be absent (``lmax <= N - 1``), missing ones are zero.
    N : int

    Returns
    -------
    ndarray, shape (*batch, N, N), complex128
        In ``su(N)`` (traceless skew-Hermitian).
    """
    N = check_N(N)
    arr = coefficient_array(omega, "from_coefficients")
    lmax = lmax_of(arr.shape[-1], "from_coefficients")
    if lmax > N - 1:
        raise ShapeError(
            f"from_coefficients: coefficients up to degree {lmax} do not fit su({N}) "
            f"(degrees l <= N - 1 = {N - 1})"
        )
    batch = arr.shape[:-1]
    flat = arr.reshape(-1, arr.shape[-1])
    W = np.zeros((flat.shape[0], N, N), dtype=np.complex128)
    scale = _norm(N)
    for m, V in bases(N, min(lmax, N - 1)):
        ls = np.arange(max(m, 1), lmax + 1)
        if ls.size == 0:
            continue
        cols = V[:, ls - m] * scale  # (N-m, nl)
        i = np.arange(N - m)
        if m == 0:
            W[:, i, i] = 1j * (flat[:, lm_index(ls, 0)] @ cols.T)
            continue
        sign = -1.0 if m % 2 else 1.0
        z = flat[:, lm_index(ls, -m)] + 1j * flat[:, lm_index(ls, m)]
        low = (sign / np.sqrt(2.0)) * (z @ cols.T)
        W[:, i + m, i] = low
        W[:, i, i + m] = -np.conj(low)
    return W.reshape(*batch, N, N)


def to_coefficients(W: ArrayLike, lmax: int | None = None) -> Array:
    r"""Real coefficients :math:`\omega_{lm}` of ``W``: the inverse of
    :func:`from_coefficients` on ``su(N)``.

    ``W`` is first projected onto ``su(N)`` (its skew-Hermitian, traceless part); each
    coefficient is then the pairing :math:`\omega_{lm} = \frac{4\pi}{N}\operatorname{Re}
    \operatorname{Tr}\big((iT_{lm})^\dagger W\big)`, computed diagonal by diagonal.

    Parameters
    ----------
    W : array_like, shape (*batch, N, N)
    lmax : int, optional
        Highest degree returned (default and maximum ``N - 1``).

    Returns
    -------
    ndarray, shape (*batch, (lmax+1)^2 - 1), float64
    """
    Wa = np.asarray(W)
    if Wa.ndim < 2 or Wa.shape[-1] != Wa.shape[-2]:
        raise ShapeError(f"to_coefficients: expected (*batch, N, N) matrices, got {Wa.shape}")
    N = check_N(Wa.shape[-1], "to_coefficients: the matrix size N")
    lmax = N - 1 if lmax is None else check_N(lmax, "lmax", minimum=1)
    if lmax > N - 1:
        raise ParameterError(f"to_coefficients: lmax must be <= N - 1 = {N - 1}, got {lmax}")
    batch = Wa.shape[:-2]
    flat = _in_blocks(Wa.reshape(-1, N, N).astype(np.complex128, copy=False))
    rows = int(np.prod(batch, dtype=np.int64))
    out = np.zeros((flat.shape[0], coefficient_count(lmax)))
    scale = _norm(N)
    for m, V in bases(N, lmax):
        ls = np.arange(max(m, 1), lmax + 1)
        cols = V[:, ls - m] / scale
        i = np.arange(N - m)
        if m == 0:
            out[:, lm_index(ls, 0)] = np.imag(flat[:, i, i]) @ cols
            continue
        sign = -1.0 if m % 2 else 1.0
        w = 0.5 * (flat[:, i + m, i] - np.conj(flat[:, i, i + m]))  # skew-Hermitian part
        z = (w @ cols) * (sign * np.sqrt(2.0))
        out[:, lm_index(ls, m)] = z.imag
        out[:, lm_index(ls, -m)] = z.real
    return out[:rows].reshape(*batch, out.shape[-1])


#: Rows of the transforms' products are padded to a multiple of this: each row's
#: coefficients then come from products of the same shape whatever the number of rows, so they
#: do not depend on how the states were batched (BLAS takes other paths, with other roundings,
#: for one row or a few than for many). A run's saved diagnostics are then the same in every
#: run, however its flushes cut the saved states into batches.
TRANSFORM_BLOCK = 8


def blocked_rows_matmul(A: Array, B: Array) -> Array:
    """``A @ B`` for ``A`` of shape ``(*batch, k)`` with the rows of ``A`` in blocks of
    :data:`TRANSFORM_BLOCK` (zero rows appended): each row's result whatever the batch."""
    a = np.asarray(A)
    flat = a.reshape(-1, a.shape[-1])
    out = _in_blocks(flat) @ B
    return out[: flat.shape[0]].reshape(*a.shape[:-1], *out.shape[1:])


def _in_blocks(flat: Array) -> Array:
    """``flat`` (``(b, ...)``) with zero rows appended up to a multiple of
    :data:`TRANSFORM_BLOCK`."""
    pad = -flat.shape[0] % TRANSFORM_BLOCK
    if pad == 0:
        return flat
    return np.concatenate([flat, np.zeros((pad, *flat.shape[1:]), dtype=flat.dtype)])
