r"""Initial vorticity: seeded random smooth fields, given coefficients, functions on the sphere."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._errors import ParameterError
from .._seeds import generator
from ._basis import degree_order
from ._basis import from_coefficients as _from_coefficients
from ._grid import from_function
from ._operators import check_N

__all__ = ["random_coefficients", "random_vorticity", "vorticity_from_function"]

Array = NDArray[Any]


def _real(v: Any, what: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
        raise ParameterError(f"{what} must be a real number, got {v!r}")
    if not np.isfinite(v):
        raise ParameterError(f"{what} must be finite, got {v!r}")
    return float(v)


def random_coefficients(
    lmax: int,
    *,
    lmin: int = 1,
    slope: float | None = None,
    rms: float = 1.0,
    seed: int | np.random.Generator | None = 0,
) -> Array:
    r"""Seeded random real coefficients of a smooth vorticity in the band ``lmin <= l <= lmax``.

    As in the random initial data of Modin & Viviani (J. Fluid Mech. 884, 2020, A22): the
    coefficients :math:`\omega_{lm}` in a band of low degrees are independent Gaussians
    (zero outside), then the whole field is scaled. The variance per degree sets the
    expected spectrum:

    * ``slope=None``: equal variance for every coefficient (white in the band); the
      expected enstrophy spectrum :math:`Z_l \propto 2l + 1`;
    * ``slope=s``: expected energy spectrum :math:`E_l \propto l^{s}`, i.e.
      :math:`\operatorname{Var}\omega_{lm} \propto l(l+1)\,l^{s}/(2l+1)`.

    The field is then scaled *exactly* (not in expectation) to the root-mean-square
    vorticity ``rms``: :math:`\frac1{4\pi}\int\omega^2 dA = \frac1{4\pi}\sum\omega_{lm}^2 =
    \mathrm{rms}^2` (enstrophy :math:`2\pi\,\mathrm{rms}^2`).

    Parameters
    ----------
    lmax : int
        Highest degree of the band (at least 1); also the size of the result.
    lmin : int
        Lowest degree of the band (default 1, at most ``lmax``); lower degrees are zero.
    slope : float, optional
        Exponent ``s`` of the expected energy spectrum; default ``None``, white in the band.
    rms : float
        The root-mean-square vorticity (positive, default 1).
    seed : int, numpy.random.Generator or None
        Seed of the coefficients (default 0; :func:`numpy.random.default_rng` semantics).

    Returns
    -------
    ndarray, shape ((lmax+1)^2 - 1,)
    """
    lmax = check_N(lmax, "lmax", minimum=1)
    lmin = check_N(lmin, "lmin", minimum=1)
    if lmin > lmax:
        raise ParameterError(f"random_coefficients: need lmin <= lmax, got {lmin} > {lmax}")
    rms = _real(rms, "rms")
    if rms <= 0:
        raise ParameterError(f"rms must be positive, got {rms}")
    rng = generator(seed, "random_coefficients: seed")
    ls, _ = degree_order(lmax)
    if slope is None:
        var = np.ones(ls.size)
    else:
        s = _real(slope, "slope")
        var = ls * (ls + 1.0) * ls**s / (2.0 * ls + 1.0)
    var = np.where(ls >= lmin, var, 0.0)
    c = rng.standard_normal(ls.size) * np.sqrt(var)
    c *= rms * np.sqrt(4.0 * np.pi) / np.sqrt(np.sum(c * c))
    return c


def random_vorticity(
    N: int,
    *,
    lmin: int = 1,
    lmax: int | None = None,
    slope: float | None = None,
    rms: float = 1.0,
    seed: int | np.random.Generator | None = 0,
) -> Array:
    r"""A seeded random smooth vorticity matrix in ``su(N)`` (see :func:`random_coefficients`).

    ``lmax`` defaults to ``min(10, N - 1)``; it must be ``<= N - 1``.

    Parameters
    ----------
    N : int
        Matrix size.
    lmin : int
        Lowest degree of the band (default 1).
    lmax : int, optional
        Highest degree of the band, at most ``N - 1`` (default ``min(10, N - 1)``).
    slope : float, optional
        Exponent of the expected energy spectrum :math:`E_l \propto l^{s}` (default
        ``None``: white in the band).
    rms : float
        The root-mean-square vorticity (positive, default 1).
    seed : int, numpy.random.Generator or None
        Seed of the coefficients (default 0).

    Returns
    -------
    ndarray, shape (N, N)
        A matrix in ``su(N)`` (complex).

    Raises
    ------
    ParameterError
        ``lmax > N - 1``, ``lmin > lmax``, a non-positive ``rms``, or a bad ``seed``.
    """
    N = check_N(N)
    lmax = min(10, N - 1) if lmax is None else check_N(lmax, "lmax", minimum=1)
    if lmax > N - 1:
        raise ParameterError(f"random_vorticity: lmax must be <= N - 1 = {N - 1}, got {lmax}")
    c = random_coefficients(lmax, lmin=lmin, slope=slope, rms=rms, seed=seed)
    return _from_coefficients(c, N)


def vorticity_from_function(
    f: Callable[[Array, Array], ArrayLike], N: int, *, oversampling: int = 2
) -> Array:
    r"""The matrix in ``su(N)`` of a vorticity given as a function on the sphere.

    ``f(colatitude, longitude)`` (radians, broadcastable arrays) is sampled on a
    Gauss–Legendre grid and transformed (``ducc0``) to its coefficients up to degree
    ``N - 1`` (:func:`~isoflow.sphere.from_function`); the mean of ``f`` is dropped.

    Parameters
    ----------
    f : callable
        ``f(colatitude, longitude) -> values`` (real).
    N : int
        Matrix size.
    oversampling : int
        Rings of the sampling grid per ``N`` (at least 1, default 2).

    Returns
    -------
    ndarray, shape (N, N)
        A matrix in ``su(N)`` (complex).
    """
    N = check_N(N)
    return _from_coefficients(from_function(f, N - 1, oversampling=oversampling), N)
