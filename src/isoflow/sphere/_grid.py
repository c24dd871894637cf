r"""Real spherical-harmonic coefficients <-> values on the sphere, through ``ducc0.sht``.

``ducc0`` (the "distinctly useful code collection" of M. Reinecke, Max Planck Institute for
Astrophysics; the engine behind healpy's and other astronomy codes' transforms) is used
because it is maintained, ships binary wheels for Linux, macOS and Windows (no compiler, no
Fortran, no FFTW needed), is exact for band-limited data on Gauss–Legendre and
Clenshaw–Curtis grids, evaluates expansions at arbitrary points, and is fast and
thread-aware (here always one thread by default; the machine may be shared).

Its conventions (checked in the tests against analytic harmonics): complex orthonormal
:math:`Y_{lm}` with the Condon–Shortley phase, real maps stored with ``m >= 0`` only
(:math:`f = \sum_l a_{l0}Y_{l0} + 2\operatorname{Re}\sum_{m>0} a_{lm} Y_{lm}`), rings from
north to south in colatitude :math:`\theta`, pixels at longitudes
:math:`\varphi_j = 2\pi j/n_\varphi`. The real coefficients of :mod:`isoflow.sphere` map to
them by :math:`a_{l0} = \omega_{l0}` and
:math:`a_{lm} = (-1)^m(\omega_{l,m} - i\,\omega_{l,-m})/\sqrt2`, ``m > 0``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._errors import DtypeError, NonFiniteError, ParameterError, ShapeError
from ._basis import coefficient_array, coefficient_count, degree_order, lmax_of
from ._operators import check_N

__all__ = [
    "GEOMETRIES",
    "analyze",
    "default_grid_shape",
    "evaluate",
    "from_function",
    "grid",
    "synthesize",
]

Array = NDArray[Any]

#: Grids of ducc0 supported here: Clenshaw–Curtis (equiangular, both poles included),
#: Gauss–Legendre, Fejér's first rule (equiangular, no poles).
GEOMETRIES = ("CC", "GL", "F1")


def _check_geometry(geometry: str) -> str:
    if geometry not in GEOMETRIES:
        raise ParameterError(f"geometry must be one of {GEOMETRIES}, got {geometry!r}")
    return geometry


def grid(ntheta: int, nphi: int, geometry: str = "CC") -> tuple[Array, Array]:
    r"""Colatitudes :math:`\theta_i` (north to south) and longitudes :math:`\varphi_j =
    2\pi j/n_\varphi` of a ``ducc0`` grid.

    ``"CC"``: :math:`\theta_i = \pi i/(n_\theta - 1)` (poles included); ``"F1"``:
    :math:`\theta_i = \pi (i + \tfrac12)/n_\theta`; ``"GL"``: the Gauss–Legendre nodes
    (:math:`\cos\theta_i` descending). Latitude is :math:`\pi/2 - \theta`.

    Parameters
    ----------
    ntheta : int
        Number of rings (at least 2).
    nphi : int
        Number of points per ring (at least 1).
    geometry : {"CC", "GL", "F1"}
        Clenshaw–Curtis (default), Gauss–Legendre or Fejér's first rule.

    Returns
    -------
    theta : ndarray, shape (ntheta,)
        Colatitudes in radians.
    phi : ndarray, shape (nphi,)
        Longitudes in radians.

    Raises
    ------
    ParameterError
        An unknown ``geometry``, or ``ntheta`` or ``nphi`` not an integer at least the
        minimum.
    """
    geometry = _check_geometry(geometry)
    ntheta = check_N(ntheta, "ntheta", minimum=2)
    nphi = check_N(nphi, "nphi", minimum=1)
    if geometry == "CC":
        theta = np.pi * np.arange(ntheta) / (ntheta - 1)
    elif geometry == "F1":
        theta = np.pi * (np.arange(ntheta) + 0.5) / ntheta
    else:
        x, _ = np.polynomial.legendre.leggauss(ntheta)
        theta = np.arccos(x[::-1])
    return theta, 2.0 * np.pi * np.arange(nphi) / nphi


def default_grid_shape(lmax: int, geometry: str = "CC") -> tuple[int, int]:
    """A grid that resolves degree ``lmax`` exactly (``ntheta`` about ``2 lmax``, ``nphi = 2
    ntheta``): twice the minimum in latitude, so that maps look smooth."""
    lmax = check_N(lmax, "lmax", minimum=1)
    _check_geometry(geometry)
    ntheta = 2 * lmax + 2
    return ntheta, 2 * ntheta


def _to_alm(omega: Array, lmax: int) -> Array:
    """Real coefficients (l >= 1) -> ducc0's complex healpy-ordered ``a_lm`` (l >= 0)."""
    ls, ms = degree_order(lmax)
    nalm = (lmax + 1) * (lmax + 2) // 2
    alm = np.zeros((*omega.shape[:-1], nalm), dtype=np.complex128)
    idx = lambda l, m: m * (2 * lmax + 1 - m) // 2 + l  # noqa: E731
    zero = ms == 0
    alm[..., idx(ls[zero], 0)] = omega[..., zero]
    pos = ms > 0
    lp, mp = ls[pos], ms[pos]
    neg = np.flatnonzero(pos) - 2 * mp  # index of (l, -m): same l, order -m
    sign = np.where(mp % 2 == 1, -1.0, 1.0)
    alm[..., idx(lp, mp)] = sign * (omega[..., pos] - 1j * omega[..., neg]) / np.sqrt(2.0)
    return alm


def _from_alm(alm: Array, lmax: int) -> Array:
    ls, ms = degree_order(lmax)
    out = np.zeros((*alm.shape[:-1], ls.size))
    idx = lambda l, m: m * (2 * lmax + 1 - m) // 2 + l  # noqa: E731
    zero = ms == 0
    out[..., zero] = alm[..., idx(ls[zero], 0)].real
    pos = ms > 0
    lp, mp = ls[pos], ms[pos]
    neg = np.flatnonzero(pos) - 2 * mp
    sign = np.where(mp % 2 == 1, -1.0, 1.0)
    a = alm[..., idx(lp, mp)]
    out[..., pos] = np.sqrt(2.0) * sign * a.real
    out[..., neg] = -np.sqrt(2.0) * sign * a.imag
    return out


def synthesize(
    omega: ArrayLike,
    ntheta: int | None = None,
    nphi: int | None = None,
    *,
    geometry: str = "CC",
    nthreads: int = 1,
) -> Array:
    r"""Values :math:`f(\theta_i, \varphi_j) = \sum_{l\ge1,m}\omega_{lm} Y_{lm}(\theta_i,
    \varphi_j)` (real harmonics) on a ``ducc0`` grid (see :func:`grid`).

    Parameters
    ----------
    omega : array_like, shape (*batch, (lmax+1)^2 - 1)
    ntheta, nphi : int, optional
        Grid shape (default :func:`default_grid_shape`). ``nphi >= 2 lmax + 1`` is needed to
        represent every order.
    geometry : {"CC", "GL", "F1"}
    nthreads : int
        ``ducc0`` threads (default 1).

    Returns
    -------
    ndarray, shape (*batch, ntheta, nphi)
    """
    import ducc0

    arr = coefficient_array(omega, "synthesize")
    lmax = lmax_of(arr.shape[-1], "synthesize")
    geometry = _check_geometry(geometry)
    dt, dp = default_grid_shape(lmax, geometry)
    ntheta = dt if ntheta is None else check_N(ntheta, "ntheta", minimum=2)
    nphi = dp if nphi is None else check_N(nphi, "nphi", minimum=1)
    alm = _to_alm(arr.reshape(-1, arr.shape[-1]), lmax)
    out = np.empty((alm.shape[0], ntheta, nphi))
    for k in range(alm.shape[0]):
        ducc0.sht.synthesis_2d(
            alm=alm[k : k + 1], spin=0, lmax=lmax, geometry=geometry, ntheta=ntheta,
            nphi=nphi, nthreads=nthreads, map=out[k : k + 1],
        )  # fmt: skip
    return out.reshape(*arr.shape[:-1], ntheta, nphi)


def analyze(values: ArrayLike, lmax: int, *, geometry: str, nthreads: int = 1) -> Array:
    r"""Real coefficients :math:`\omega_{lm}`, ``1 <= l <= lmax``, of values on a ``ducc0``
    grid (the inverse of :func:`synthesize` on the same ``geometry``, for band-limited data).

    Exact for functions of degree ``<= lmax`` when the grid is fine enough: Gauss–Legendre
    needs ``ntheta >= lmax + 1``, Clenshaw–Curtis ``ntheta >= lmax + 2`` (ducc0 upsamples
    internally), and ``nphi >= 2 lmax + 1``. The mean (``l = 0``) is dropped: a vorticity on
    the closed sphere has zero mean, and ``su(N)`` has no room for it.

    Parameters
    ----------
    values : array_like, shape (*batch, ntheta, nphi)
    lmax : int
    geometry : {"CC", "GL", "F1"}
        The grid the values are given on (required: values on another grid give wrong
        coefficients without any error; :func:`synthesize` and :func:`grid` default to
        ``"CC"``).
    nthreads : int
        ``ducc0`` threads (default 1).

    Returns
    -------
    ndarray, shape (*batch, (lmax+1)^2 - 1)
    """
    import ducc0

    lmax = check_N(lmax, "lmax", minimum=1)
    geometry = _check_geometry(geometry)
    v = np.asarray(values)
    if v.dtype.kind not in "biuf":
        raise ShapeError(f"analyze: values must be real numbers, got dtype {v.dtype}")
    if v.ndim < 2:
        raise ShapeError(f"analyze: values must have shape (*batch, ntheta, nphi), got {v.shape}")
    if not np.all(np.isfinite(v)):
        raise NonFiniteError("analyze: values must be finite (found NaN or Inf)")
    ntheta, nphi = v.shape[-2:]
    need = lmax + 1 if geometry in ("GL", "F1") else lmax + 2
    if ntheta < need or nphi < 2 * lmax + 1:
        raise ShapeError(
            f"analyze: a {geometry} grid of shape ({ntheta}, {nphi}) cannot resolve degree "
            f"{lmax}; need ntheta >= {need} and nphi >= {2 * lmax + 1}"
        )
    flat = np.ascontiguousarray(v.reshape(-1, ntheta, nphi), dtype=np.float64)
    nalm = (lmax + 1) * (lmax + 2) // 2
    alm = np.empty((flat.shape[0], nalm), dtype=np.complex128)
    for k in range(flat.shape[0]):
        ducc0.sht.analysis_2d(
            map=flat[k : k + 1], spin=0, lmax=lmax, geometry=geometry, nthreads=nthreads,
            alm=alm[k : k + 1],
        )  # fmt: skip
    return _from_alm(alm, lmax).reshape(*v.shape[:-2], coefficient_count(lmax))


def evaluate(
    omega: ArrayLike, colatitude: ArrayLike, longitude: ArrayLike, *, nthreads: int = 1
) -> Array:
    r"""Values of :math:`\sum \omega_{lm} Y_{lm}` at arbitrary points (``ducc0``'s
    non-uniform synthesis, relative accuracy about ``1e-10``).

    Parameters
    ----------
    omega : array_like, shape ((lmax+1)^2 - 1,)
        One set of coefficients.
    colatitude, longitude : array_like
        Broadcast together; radians, colatitude in :math:`[0, \pi]`.
    nthreads : int
        ``ducc0`` threads (default 1).

    Returns
    -------
    ndarray, the broadcast shape of ``colatitude`` and ``longitude``
    """
    import ducc0

    arr = coefficient_array(omega, "evaluate")
    if arr.ndim != 1:
        raise ShapeError(f"evaluate: give one set of coefficients, got shape {arr.shape}")
    lmax = lmax_of(arr.shape[-1], "evaluate")
    th, ph = np.broadcast_arrays(np.asarray(colatitude, float), np.asarray(longitude, float))
    loc = np.stack([np.clip(th.ravel(), 0.0, np.pi), np.mod(ph.ravel(), 2.0 * np.pi)], axis=1)
    alm = _to_alm(arr[None, :], lmax)
    vals = ducc0.sht.synthesis_general(
        alm=alm, spin=0, lmax=lmax, loc=np.ascontiguousarray(loc), epsilon=1e-10,
        nthreads=nthreads,
    )  # fmt: skip
    return vals[0].reshape(th.shape)


def _real_values(values: ArrayLike, what: str) -> Array:
    """A function's values on a grid as finite float64, or a one-line error: a vorticity is
    real, and casting complex values would drop their imaginary parts silently."""
    arr = np.asarray(values)
    if arr.dtype.kind == "c":
        imag = float(np.max(np.abs(arr.imag))) if arr.size else 0.0
        if imag > 0:
            raise DtypeError(
                f"{what} returned complex values (largest imaginary part {imag:.3g}); a "
                "vorticity is real: return the real field"
            )
        arr = arr.real
    if arr.dtype.kind not in "biuf":
        raise DtypeError(f"{what} returned {arr.dtype} values, not real numbers")
    out = arr.astype(np.float64)
    if not np.all(np.isfinite(out)):
        raise NonFiniteError(f"{what} returned non-finite values (NaN or Inf)")
    return out


def from_function(
    f: Callable[[Array, Array], ArrayLike],
    lmax: int,
    *,
    oversampling: int = 2,
    nthreads: int = 1,
) -> Array:
    r"""Real coefficients (``1 <= l <= lmax``) of a function on the sphere.

    ``f(colatitude, longitude)`` is called once with broadcastable arrays of a Gauss–Legendre
    grid of ``oversampling * (lmax + 1)`` rings and returns the values; the grid is finer than
    exactness for degree ``lmax`` needs, which reduces aliasing of the degrees above
    ``lmax`` (for a band-limited ``f`` of degree
    :math:`\le 2\,\mathrm{oversampling}\,(l_{max}+1) - 1 - l_{max}` the quadrature, and so the
    result, is exact). The mean of ``f`` is dropped (see :func:`analyze`).

    Parameters
    ----------
    f : callable
        ``f(colatitude, longitude) -> values``, radians in, real values out (complex values
        with a negligible imaginary part are accepted).
    lmax : int
        Highest degree (at least 1).
    oversampling : int
        Rings of the grid per ``lmax + 1`` (at least 1, default 2).
    nthreads : int
        Threads of the ``ducc0`` transform (default 1).

    Returns
    -------
    ndarray, shape ((lmax+1)^2 - 1,)

    Raises
    ------
    ParameterError
        ``f`` not callable, or a bad ``lmax`` or ``oversampling``.
    ShapeError
        Values that do not broadcast to the grid.
    DtypeError, NonFiniteError
        Values that are not real numbers, or not finite.
    """
    lmax = check_N(lmax, "lmax", minimum=1)
    if not callable(f):
        raise ParameterError(f"from_function: f must be callable, got {type(f).__name__}")
    oversampling = check_N(oversampling, "oversampling", minimum=1)
    ntheta = oversampling * (lmax + 1)
    nphi = 2 * ntheta
    theta, phi = grid(ntheta, nphi, "GL")
    vals = _real_values(f(theta[:, None], phi[None, :]), "from_function: f")
    try:
        vals = np.broadcast_to(vals, (ntheta, nphi))
    except ValueError:
        raise ShapeError(
            f"from_function: f returned shape {vals.shape}, which does not broadcast to the "
            f"grid ({ntheta}, {nphi})"
        ) from None
    return analyze(vals, lmax, geometry="GL", nthreads=nthreads)
