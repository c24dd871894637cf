r"""Diagnostics of the two fields of magnetohydrodynamics on the sphere.

The magnetic potential :math:`\theta` (the magnetic field is :math:`b = n \times \nabla\theta`,
tangent to the level lines of :math:`\theta`: its *field lines*) is quantized like the
vorticity, :math:`\Theta = i\,T(\theta) \in \mathfrak{su}(N)`; the current density
:math:`j = \Delta\theta` is :math:`J = \Delta_N\Theta`. Integrals use the trace pairing
:math:`\int f g\,dA \leftrightarrow \frac{4\pi}{N}\operatorname{Tr}(T(f)T(g))` as in
:mod:`isoflow.sphere._diagnostics`, so every number converges to its continuum value.
The kinetic side is that module's: :func:`~isoflow.sphere.energy`,
:func:`~isoflow.sphere.energy_spectrum`; the Casimirs :math:`\int\theta^k dA` are
:func:`~isoflow.sphere.casimirs` of :math:`\Theta`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._eig import eigh_diagonal
from .._errors import ParameterError, ShapeError
from .._reductions import real_inner
from ._diagnostics import _coefficients_of, enstrophy_spectrum
from ._operators import as_matrices, laplacian

__all__ = ["cross_casimirs", "current", "magnetic_energy", "magnetic_energy_spectrum"]

Array = NDArray[Any]


def current(Theta: ArrayLike) -> Array:
    r"""The current density matrix :math:`J = \Delta_N\Theta` (:math:`j = \Delta\theta`),
    ``O(N^2)`` per matrix; the same as :func:`~isoflow.sphere.laplacian`."""
    return laplacian(Theta)


def magnetic_energy(Theta: ArrayLike) -> Array:
    r"""Magnetic energy :math:`E_M = -\frac{2\pi}{N}\operatorname{Re}\operatorname{Tr}
    (J^\dagger\Theta)`, :math:`J = \Delta_N\Theta`: the quantized
    :math:`\frac12\int|b|^2 dA = -\frac12\int\theta\,j\,dA`.

    In coefficients :math:`E_M = \frac12\sum_{l,m} l(l+1)\,\theta_{lm}^2` exactly. ``O(N^2)``
    per matrix.

    Returns
    -------
    ndarray, shape batch
    """
    flat, batch, N = as_matrices(Theta, "magnetic_energy")
    J = laplacian(flat)
    tr = real_inner(J, flat)
    return (-2.0 * np.pi / N * tr).reshape(batch)


def magnetic_energy_spectrum(data: ArrayLike) -> Array:
    r"""Magnetic energy spectrum :math:`E^M_l = l(l+1)\sum_m\theta_{lm}^2 = \sum_m
    j_{lm}^2/(l(l+1))`, ``l = 1..lmax``: the kinetic spectrum's formula
    (:func:`~isoflow.sphere.energy_spectrum`) with the current in place of the vorticity.

    ``data``: magnetic potentials ``(*batch, N, N)`` (complex) or real coefficients of
    :math:`\theta`. :math:`\sum_l E^M_l = 2E_M` (:func:`magnetic_energy`).

    Returns
    -------
    ndarray, shape (*batch, lmax)
    """
    c, _ = _coefficients_of(data, "magnetic_energy_spectrum")
    Z = enstrophy_spectrum(c)
    ls = np.arange(1, Z.shape[-1] + 1)
    return Z * (ls * (ls + 1.0))


def cross_casimirs(Theta: ArrayLike, W: ArrayLike, kmax: int = 5) -> Array:
    r"""The cross Casimirs :math:`H_k = \frac{4\pi}{N}\operatorname{Tr}\big((-iW)(-i\Theta)^k
    \big) \approx \int_{S^2}\omega\,\theta^k\,dA`, ``k = 1..kmax``.

    Conserved by ideal MHD (and by IsoMP on the pairs, to rounding), as are
    :math:`\int\theta^k dA` (:func:`~isoflow.sphere.casimirs` of :math:`\Theta`).
    :math:`H_1 = \int\omega\theta\,dA = -\int u\cdot b\,dA` is minus the cross helicity.
    Computed from one eigendecomposition of :math:`-i\Theta` (:math:`H_k = \frac{4\pi}{N}
    \sum_i d_i\lambda_i^k`, :math:`d_i` the diagonal of :math:`-iW` in its eigenvectors).

    Parameters
    ----------
    Theta : array_like, shape (*batch, N, N)
        Magnetic potentials in ``su(N)`` (complex).
    W : array_like, shape (*batch, N, N)
        Vorticities of the same shape.
    kmax : int
        Highest power ``k`` (at least 1, default 5).

    Returns
    -------
    ndarray, shape (*batch, kmax)
    """
    if isinstance(kmax, bool) or not isinstance(kmax, (int, np.integer)) or kmax < 1:
        raise ParameterError(f"cross_casimirs: kmax must be an integer >= 1, got {kmax!r}")
    th, batch, N = as_matrices(Theta, "cross_casimirs")
    w, wbatch, M = as_matrices(W, "cross_casimirs")
    if (wbatch, M) != (batch, N):
        raise ShapeError(
            f"cross_casimirs: Theta and W must have one shape, got {(*batch, N, N)} and "
            f"{(*wbatch, M, M)}"
        )
    lam, d = eigh_diagonal(-1j * th, -1j * w)
    ks = np.arange(1, int(kmax) + 1)
    H = (4.0 * np.pi / N) * np.sum(d[:, None, :] * lam[:, None, :] ** ks[:, None], axis=-1)
    return H.reshape(*batch, int(kmax))
