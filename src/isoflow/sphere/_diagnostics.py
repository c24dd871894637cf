r"""Diagnostics of vorticity matrices: Casimirs, energy, enstrophy, spectra, angular momentum.

Every integral over the sphere is quantized with the trace pairing
:math:`\int_{S^2} f\,g\,dA \leftrightarrow \frac{4\pi}{N}\operatorname{Tr}(F G)` of the
Hermitian matrices :math:`F = T(f)`, under which the quantized harmonics are orthonormal, so
that these numbers are those of the band-limited continuum field with the same coefficients
and converge to the continuum values as ``N`` grows.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._errors import ParameterError, ShapeError
from .._reductions import real_inner, trace
from ._basis import coefficient_array, lmax_of, to_coefficients
from ._operators import as_matrices, hbar, solve_poisson

__all__ = [
    "angular_momentum",
    "casimirs",
    "energy",
    "energy_spectrum",
    "enstrophy",
    "enstrophy_spectrum",
    "vorticity_levels",
]

Array = NDArray[Any]


def vorticity_levels(W: ArrayLike) -> Array:
    r"""The spectrum of the vorticity: eigenvalues of the Hermitian :math:`-iW`, ascending.

    All of them are Casimirs of the isospectral flow (the quantized distribution function of
    the vorticity values; :math:`-iW` is :math:`T(\omega)` for :math:`W = i\,T(\omega)`).

    Returns
    -------
    ndarray, shape (*batch, N)
    """
    flat, batch, N = as_matrices(W, "vorticity_levels")
    return np.linalg.eigvalsh(-1j * flat).reshape(*batch, N)


def casimirs(W: ArrayLike, kmax: int = 6) -> Array:
    r"""The normalized Casimirs :math:`C_k = \frac{4\pi}{N}\operatorname{Tr}\big((-iW)^k\big)
    \approx \int_{S^2}\omega^k\,dA`, ``k = 2..kmax``.

    :math:`\operatorname{Tr}(W^k) = i^k\,\frac{N}{4\pi} C_k` (real for even ``k``, imaginary
    for odd ``k``). Computed from the eigenvalues (:func:`vorticity_levels`), which is
    accurate where ``W^k`` formed by products would lose digits.

    Returns
    -------
    ndarray, shape (*batch, kmax - 1)
    """
    if isinstance(kmax, bool) or not isinstance(kmax, (int, np.integer)) or kmax < 2:
        raise ParameterError(f"casimirs: kmax must be an integer >= 2, got {kmax!r}")
    lam = vorticity_levels(W)
    N = lam.shape[-1]
    ks = np.arange(2, int(kmax) + 1)
    return (4.0 * np.pi / N) * np.sum(lam[..., None, :] ** ks[:, None], axis=-1)


def energy(W: ArrayLike) -> Array:
    r"""Kinetic energy :math:`H = -\frac{2\pi}{N}\operatorname{Re}\operatorname{Tr}(P^\dagger
    W)`, :math:`\Delta_N P = W`: the quantized :math:`\frac12\int|u|^2 dA =
    -\frac12\int\psi\,\omega\,dA`.

    In coefficients, :math:`H = \frac12\sum_{l,m}\omega_{lm}^2/(l(l+1))` exactly (the
    Laplacian is diagonal in the :math:`T_{lm}`). ``O(N^2)`` per matrix. This is the
    brief form :math:`-\tfrac12\operatorname{Tr}(P^\dagger W)` times :math:`4\pi/N`, the
    factor that makes it converge to the continuum energy.

    Returns
    -------
    ndarray, shape batch
    """
    flat, batch, N = as_matrices(W, "energy")
    P = solve_poisson(flat)
    tr = real_inner(P, flat)  # the same bits for a state in any batch (isoflow._reductions)
    return (-2.0 * np.pi / N * tr).reshape(batch)


def enstrophy(W: ArrayLike) -> Array:
    r"""Enstrophy :math:`Z = \frac12\int\omega^2 dA \leftrightarrow
    -\frac{2\pi}{N}\operatorname{Tr}(W^2) = \frac{2\pi}{N}\|W\|_F^2 = \frac12\sum\omega_{lm}^2`
    (of the traceless part of ``W``). A Casimir: ``C_2 / 2`` of :func:`casimirs`.

    Returns
    -------
    ndarray, shape batch
    """
    flat, batch, N = as_matrices(W, "enstrophy")
    tr = trace(flat)
    sq = np.sum(np.abs(flat) ** 2, axis=(-2, -1)) - np.abs(tr) ** 2 / N
    return (2.0 * np.pi / N * sq).reshape(batch)


def _coefficients_of(data: ArrayLike, what: str) -> tuple[Array, int]:
    """Coefficients from either matrices (``(*batch, N, N)``, complex) or coefficients."""
    arr = np.asarray(data)
    if np.iscomplexobj(arr):
        if arr.ndim < 2 or arr.shape[-1] != arr.shape[-2]:
            raise ShapeError(f"{what}: complex input must be (*batch, N, N) matrices")
        c = to_coefficients(arr)
        return c, arr.shape[-1] - 1
    c = coefficient_array(arr, what)
    return c, lmax_of(c.shape[-1], what)


def enstrophy_spectrum(data: ArrayLike) -> Array:
    r"""Enstrophy per degree :math:`Z_l = \sum_m \omega_{lm}^2`, ``l = 1..lmax``.

    ``data`` is either matrices ``(*batch, N, N)`` (complex; ``O(N^3)`` through
    :func:`~isoflow.sphere.to_coefficients`) or real coefficients ``(*batch, (lmax+1)^2-1)``.
    :math:`\sum_l Z_l = 2 Z` (:func:`enstrophy`).

    Returns
    -------
    ndarray, shape (*batch, lmax)
    """
    c, lmax = _coefficients_of(data, "enstrophy_spectrum")
    sq = c**2
    starts = np.arange(1, lmax + 1) ** 2 - 1
    return np.add.reduceat(sq, starts, axis=-1)


def energy_spectrum(data: ArrayLike) -> Array:
    r"""Energy spectrum :math:`E_l = \sum_m |\omega_{lm}|^2/(l(l+1))`, ``l = 1..lmax``.

    Same input as :func:`enstrophy_spectrum`. :math:`\sum_l E_l = 2H` (:func:`energy`).

    Parameters
    ----------
    data : array_like, shape (*batch, N, N) or (*batch, n_coefficients)
        Vorticity matrices (complex) or real coefficients of :math:`\omega`.

    Returns
    -------
    ndarray, shape (*batch, lmax)
    """
    Z = enstrophy_spectrum(data)
    ls = np.arange(1, Z.shape[-1] + 1)
    return Z / (ls * (ls + 1.0))


def angular_momentum(W: ArrayLike) -> Array:
    r"""The vorticity's angular momentum :math:`L_a = \int_{S^2}\omega\,x_a\,dA
    \leftrightarrow \frac{4\pi}{N}\operatorname{Re}\operatorname{Tr}\big(X_a(-iW)\big)`,
    :math:`X_a = \hbar J_a`, ``a = x, y, z``; ``O(N)`` per matrix.

    :math:`L = \sqrt{4\pi/3}\,(\omega_{11}, \omega_{1,-1}, \omega_{10})` in the real
    coefficients. On a non-rotating sphere all three are conserved (and so by IsoMP); on a
    rotating sphere only :math:`L_z`.

    Parameters
    ----------
    W : array_like, shape (*batch, N, N)
        Vorticity matrices in ``su(N)`` (complex).

    Returns
    -------
    ndarray, shape (*batch, 3)
    """
    flat, batch, N = as_matrices(W, "angular_momentum")
    Om = -1j * flat
    a = np.arange(N - 1)
    c = np.sqrt((a + 1.0) * (N - a - 1.0))  # (J_+)_{a+1, a}
    # contiguous rows: each row summed the same way whatever the batch (a strided reduction
    # sums in another order, and which one depends on the number of rows)
    tp = np.sum(np.ascontiguousarray(c * Om[:, a, a + 1]), axis=-1)  # Tr(J_+ Om)
    tm = np.sum(np.ascontiguousarray(c * Om[:, a + 1, a]), axis=-1)  # Tr(J_- Om)
    d = np.ascontiguousarray((np.arange(N) - 0.5 * (N - 1)) * np.diagonal(Om, axis1=-2, axis2=-1))
    t3 = np.sum(d, axis=-1)
    tx = 0.5 * (tp + tm)
    ty = -0.5j * (tp - tm)
    L = np.stack([tx.real, ty.real, t3.real], axis=-1) * (4.0 * np.pi / N * hbar(N))
    return L.reshape(*batch, 3)
