r"""Figures of vorticity on the sphere: maps, orthographic views, spectra, invariants, movies.

Every function returns a :class:`matplotlib.figure.Figure` built without ``pyplot`` (no
global state, renders headless). Inputs are vorticity matrices ``(N, N)`` (complex) or real
coefficients (the layout of :func:`isoflow.sphere.lm_index`); matplotlib is imported when a
function is called. The orthographic projection is computed here (no cartopy): each pixel of
the disk is mapped to its point on the sphere and the expansion is evaluated there exactly
with ``ducc0`` (:func:`isoflow.sphere.evaluate`).
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._errors import NonFiniteError, ParameterError, ShapeError
from ._basis import coefficient_array, lmax_of, to_coefficients
from ._grid import default_grid_shape, evaluate, synthesize
from ._operators import check_N

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = [
    "SPECTRUM_FLOOR",
    "animate",
    "draw_energy_spectrum",
    "draw_field_lines",
    "draw_map",
    "draw_orthographic",
    "plot_energy_spectrum",
    "plot_invariants",
    "plot_map",
    "plot_mhd",
    "plot_orthographic",
]

Array = NDArray[Any]
_CMAP = "RdBu_r"


def _coefficients(data: ArrayLike) -> Array:
    """Real coefficients of matrices ``(*batch, N, N)`` or of coefficients themselves."""
    arr = np.asarray(data)
    if np.iscomplexobj(arr):
        if arr.ndim < 2 or arr.shape[-1] != arr.shape[-2]:
            raise ShapeError(f"expected (*batch, N, N) vorticity matrices, got {arr.shape}")
        return to_coefficients(arr)
    c = coefficient_array(arr, "coefficients")
    lmax_of(c.shape[-1], "coefficients")
    return c


def _number(value: Any) -> float | None:
    """``value`` as a float if it is a real number (not a bool), else ``None``."""
    if isinstance(value, bool | np.bool_) or not isinstance(value, int | float | np.number):
        return None
    return None if np.iscomplexobj(value) else float(value)


def _center(center: Any, what: str) -> tuple[float, float]:
    """A viewpoint ``(latitude, longitude)`` in degrees, checked."""
    pair = tuple(center) if isinstance(center, Sequence | np.ndarray) else ()
    values = [_number(v) for v in pair]
    if len(values) != 2 or None in values:
        raise ParameterError(
            f"{what}: a centre is (latitude, longitude) in degrees, got {center!r}"
        )
    lat, lon = float(values[0]), float(values[1])  # type: ignore[arg-type]
    if not (math.isfinite(lat) and math.isfinite(lon) and -90.0 <= lat <= 90.0):
        raise ParameterError(
            f"{what}: a centre needs a finite latitude in [-90, 90] and a finite longitude "
            f"(degrees), got {center!r}"
        )
    return lat, lon


def _positive(value: Any, what: str) -> float:
    """A positive finite number (a resolution in dots per inch, a colour limit)."""
    x = _number(value)
    if x is None or not (math.isfinite(x) and x > 0):
        raise ParameterError(f"{what} must be a positive finite number, got {value!r}")
    return x


def _vmax(vmax: Any, what: str) -> float | None:
    return None if vmax is None else _positive(vmax, f"{what}: vmax")


def _series(values: ArrayLike, n: int | None, what: str) -> Array:
    """A finite real time series of ``n`` entries (any length ``>= 1`` when ``n`` is None)."""
    arr = np.asarray(values)
    if arr.dtype.kind not in "iuf":
        raise ParameterError(f"{what} must be real numbers, got dtype {arr.dtype}")
    expected = "(n_t,) with n_t >= 1" if n is None else f"({n},), one per time"
    if arr.ndim != 1 or arr.size == 0 or (n is not None and arr.size != n):
        raise ShapeError(f"{what} must have shape {expected}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise NonFiniteError(f"{what} must be finite (found NaN or Inf)")
    return arr.astype(float)


def _symmetric_limit(values: Array, vmax: float | None) -> float:
    if vmax is not None:
        return float(vmax)
    v = float(np.max(np.abs(values))) if values.size else 1.0
    return v if v > 0 else 1.0


def _map_grid(lmax: int, ntheta: Any, nphi: Any, where: str) -> tuple[int, int]:
    """The equiangular grid of a map: ``ntheta, nphi`` checked (at least 2 rings and 1
    longitude), or by default about two points per wavelength of degree ``lmax``, at least
    ``90 x 180``."""
    dt, dp = default_grid_shape(lmax)
    ntheta = max(dt, 90) if ntheta is None else check_N(ntheta, f"{where}: ntheta", minimum=2)
    nphi = max(dp, 180) if nphi is None else check_N(nphi, f"{where}: nphi", minimum=1)
    return ntheta, nphi


def draw_map(
    ax: Axes,
    data: ArrayLike,
    *,
    ntheta: int | None = None,
    nphi: int | None = None,
    vmax: float | None = None,
    cmap: str = _CMAP,
    interpolation: str = "bilinear",
) -> Any:
    """Draw the vorticity on a global latitude–longitude map into ``ax``; returns the image.

    The field is synthesized on an equiangular (Clenshaw–Curtis) grid, by default about two
    points per wavelength of degree ``lmax`` and at least ``90 x 180``; ``interpolation`` is
    matplotlib's (``"nearest"`` shows the grid cells and makes smaller PNG files).

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        The axes to draw into (labelled in degrees of longitude and latitude).
    data : array_like, shape (N, N) or (n_coefficients,)
        One vorticity field: a matrix (complex) or real coefficients.
    ntheta : int, optional
        Number of grid rings in latitude (at least 2). Default: ``max(2 lmax + 2, 90)``.
    nphi : int, optional
        Number of grid points in longitude (at least 1). Default:
        ``max(4 lmax + 4, 180)``.
    vmax : float, optional
        Colour limit (positive): the colours span ``[-vmax, vmax]``. Default: the largest
        ``|omega|`` on the grid.
    cmap : str
        Name of a matplotlib colour map (default ``"RdBu_r"``).
    interpolation : str
        matplotlib's image interpolation (default ``"bilinear"``).

    Returns
    -------
    matplotlib.image.AxesImage
        The image (for a colour bar).

    Raises
    ------
    ShapeError
        ``data`` is not one field.
    ParameterError
        A bad ``ntheta``, ``nphi`` or ``vmax``.
    """
    c = _coefficients(data)
    if c.ndim != 1:
        raise ShapeError(f"draw_map: give one vorticity field, got shape {c.shape}")
    vmax = _vmax(vmax, "draw_map")
    lmax = lmax_of(c.shape[-1], "draw_map")
    ntheta, nphi = _map_grid(lmax, ntheta, nphi, "draw_map")
    vals = synthesize(c, ntheta, nphi, geometry="CC")
    vals = np.concatenate([vals, vals[:, :1]], axis=1)  # close the longitude circle
    lim = _symmetric_limit(vals, vmax)
    im = ax.imshow(
        vals, extent=(0.0, 360.0, -90.0, 90.0), origin="upper", cmap=cmap, vmin=-lim,
        vmax=lim, aspect="auto", interpolation=interpolation,
    )  # fmt: skip
    ax.set_xlabel("longitude [deg]")
    ax.set_ylabel("latitude [deg]")
    ax.set_xticks(np.arange(0, 361, 60))
    ax.set_yticks(np.arange(-90, 91, 30))
    return im


def draw_field_lines(
    ax: Axes,
    theta: ArrayLike,
    *,
    levels: int = 14,
    ntheta: int | None = None,
    nphi: int | None = None,
    color: str = "k",
    linewidth: float = 0.6,
) -> Any:
    r"""Draw magnetic field lines into a map drawn by :func:`draw_map`: the level lines of the
    magnetic potential :math:`\theta` (the field :math:`b = n\times\nabla\theta` is tangent to
    them, and stronger where they crowd); returns the contour set.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        The axes of a map drawn by :func:`draw_map`.
    theta : array_like, shape (N, N) or (n_coefficients,)
        One magnetic potential: a matrix (complex) or real coefficients.
    levels : int
        Number of lines (default 14), at equally spaced values strictly between the extremes
        of :math:`\theta`.
    ntheta, nphi : int, optional
        Grid on which :math:`\theta` is synthesized, as in :func:`draw_map` (at least 2
        rings and 1 longitude). Default: ``max(2 lmax + 2, 90)`` rings and
        ``max(4 lmax + 4, 180)`` longitudes, the grid of :func:`draw_map`'s default.
    color : str
        Colour of the lines (matplotlib colour, default ``"k"``).
    linewidth : float
        Width of the lines in points (default 0.6).

    Returns
    -------
    matplotlib.contour.QuadContourSet or None
        The contour set, or ``None`` for a constant potential (no field, no lines).

    Raises
    ------
    ShapeError
        ``theta`` is not one field.
    ParameterError
        A bad ``ntheta`` or ``nphi`` (``0`` included).
    """
    c = _coefficients(theta)
    if c.ndim != 1:
        raise ShapeError(f"draw_field_lines: give one magnetic potential, got shape {c.shape}")
    lmax = lmax_of(c.shape[-1], "draw_field_lines")
    ntheta, nphi = _map_grid(lmax, ntheta, nphi, "draw_field_lines")
    vals = synthesize(c, ntheta, nphi, geometry="CC")
    vals = np.concatenate([vals, vals[:, :1]], axis=1)  # close the longitude circle
    lon = np.linspace(0.0, 360.0, nphi + 1)
    lat = np.linspace(90.0, -90.0, ntheta)  # CC rings: north pole to south pole
    lo, hi = float(np.min(vals)), float(np.max(vals))
    if not hi > lo:  # a constant potential: no field, no lines
        return None
    steps = np.linspace(lo, hi, int(levels) + 2)[1:-1]
    return ax.contour(lon, lat, vals, levels=steps, colors=color, linewidths=linewidth)


def _ortho_points(center: tuple[float, float], resolution: int) -> tuple[Array, Array, Array]:
    """Colatitude, longitude of the visible disk's pixels, and the disk mask."""
    lat0, lon0 = np.deg2rad(center[0]), np.deg2rad(center[1])
    x = np.linspace(-1.0, 1.0, resolution)
    X, Y = np.meshgrid(x, x[::-1])  # screen: x east, y north, row 0 at the top
    inside = X**2 + Y**2 <= 1.0
    Zv = np.sqrt(np.clip(1.0 - X**2 - Y**2, 0.0, None))
    c = np.array([np.cos(lat0) * np.cos(lon0), np.cos(lat0) * np.sin(lon0), np.sin(lat0)])
    e = np.array([-np.sin(lon0), np.cos(lon0), 0.0])
    n = np.cross(c, e)
    P = X[..., None] * e + Y[..., None] * n + Zv[..., None] * c
    colat = np.arccos(np.clip(P[..., 2], -1.0, 1.0))
    lon = np.mod(np.arctan2(P[..., 1], P[..., 0]), 2.0 * np.pi)
    return colat, lon, inside


def _project(lat: Array, lon: Array, center: tuple[float, float]) -> tuple[Array, Array, Array]:
    """Screen coordinates of points (radians) and whether they face the viewer."""
    lat0, lon0 = np.deg2rad(center[0]), np.deg2rad(center[1])
    p = np.stack([np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)], axis=-1)
    c = np.array([np.cos(lat0) * np.cos(lon0), np.cos(lat0) * np.sin(lon0), np.sin(lat0)])
    e = np.array([-np.sin(lon0), np.cos(lon0), 0.0])
    n = np.cross(c, e)
    return p @ e, p @ n, p @ c > 0


def draw_orthographic(
    ax: Axes,
    data: ArrayLike,
    *,
    center: tuple[float, float] = (30.0, 0.0),
    resolution: int = 200,
    vmax: float | None = None,
    cmap: str = _CMAP,
    graticule: bool = True,
) -> Any:
    """Draw the vorticity seen from above ``center = (latitude, longitude)`` [deg] into
    ``ax`` (orthographic projection of the visible hemisphere, ``resolution`` pixels across,
    at least 3); returns the image.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
        The axes to draw into (their frame is switched off, the aspect made equal).
    data : array_like, shape (N, N) or (n_coefficients,)
        One vorticity field: a matrix (complex) or real coefficients.
    center : (float, float)
        The viewpoint ``(latitude, longitude)`` in degrees (default ``(30, 0)``), a finite
        latitude in ``[-90, 90]`` and a finite longitude.
    resolution : int
        Pixels across the disk (at least 3, default 200).
    vmax : float, optional
        Colour limit (positive): the colours span ``[-vmax, vmax]``. Default: the largest
        ``|omega|`` on the visible disk.
    cmap : str
        Name of a matplotlib colour map (default ``"RdBu_r"``).
    graticule : bool
        Whether to draw the parallels (every 30 degrees up to ``±60``) and the meridians
        (every 30 degrees); default ``True``.

    Returns
    -------
    matplotlib.image.AxesImage
        The image (for a colour bar).

    Raises
    ------
    ShapeError
        ``data`` is not one field.
    ParameterError
        A bad ``center``, ``resolution`` or ``vmax``.
    """
    c = _coefficients(data)
    if c.ndim != 1:
        raise ShapeError(f"draw_orthographic: give one vorticity field, got shape {c.shape}")
    center = _center(center, "draw_orthographic")
    resolution = check_N(resolution, "draw_orthographic: resolution", minimum=3)
    vmax = _vmax(vmax, "draw_orthographic")
    colat, lon, inside = _ortho_points(center, resolution)
    vals = np.full(colat.shape, np.nan)
    vals[inside] = evaluate(c, colat[inside], lon[inside])
    lim = _symmetric_limit(vals[inside], vmax)
    im = ax.imshow(
        np.ma.masked_invalid(vals), extent=(-1, 1, -1, 1), origin="upper", cmap=cmap,
        vmin=-lim, vmax=lim, interpolation="bilinear",
    )  # fmt: skip
    t = np.linspace(0, 2 * np.pi, 361)
    ax.plot(np.cos(t), np.sin(t), color="0.2", lw=0.8)
    if graticule:
        s = np.linspace(-np.pi, np.pi, 361)
        for la in np.deg2rad(np.arange(-60, 61, 30)):
            x, y, vis = _project(np.full_like(s, la), s, center)
            ax.plot(np.where(vis, x, np.nan), np.where(vis, y, np.nan), color="0.4", lw=0.4)
        s = np.linspace(-np.pi / 2, np.pi / 2, 181)
        for lo in np.deg2rad(np.arange(0, 360, 30)):
            x, y, vis = _project(s, np.full_like(s, lo), center)
            ax.plot(np.where(vis, x, np.nan), np.where(vis, y, np.nan), color="0.4", lw=0.4)
    ax.set_xlim(-1.05, 1.05)
    ax.set_ylim(-1.05, 1.05)
    ax.set_aspect("equal")
    ax.set_axis_off()
    return im


def _title(N: int | None, extra: str | None) -> str:
    base = "vorticity $\\omega$" + (f", N = {N}" if N else "")
    return base + (f", {extra}" if extra else "")


def _N_of(data: ArrayLike) -> int | None:
    arr = np.asarray(data)
    return int(arr.shape[-1]) if np.iscomplexobj(arr) and arr.ndim >= 2 else None


def plot_map(
    data: ArrayLike,
    *,
    title: str | None = None,
    vmax: float | None = None,
    cmap: str = _CMAP,
    ntheta: int | None = None,
    nphi: int | None = None,
) -> Figure:
    """The vorticity of one matrix (or coefficient set) on a latitude–longitude map.

    Parameters
    ----------
    data : array_like, shape (N, N) or (n_coefficients,)
        One vorticity field: a matrix (complex) or real coefficients.
    title : str, optional
        Title of the axes. Default: ``"vorticity ω, N = ..., equirectangular map"`` (``N``
        only when ``data`` is a matrix).
    vmax : float, optional
        Colour limit (positive): the colours span ``[-vmax, vmax]``. Default: the largest
        ``|omega|`` on the grid.
    cmap : str
        Name of a matplotlib colour map (default ``"RdBu_r"``).
    ntheta, nphi : int, optional
        The synthesis grid, as in :func:`draw_map` (default: at least ``90 x 180``).

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    ShapeError
        ``data`` is not one field.
    ParameterError
        A bad ``ntheta``, ``nphi`` or ``vmax``.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8, 4.2), layout="constrained")
    ax = fig.subplots()
    im = draw_map(ax, data, ntheta=ntheta, nphi=nphi, vmax=vmax, cmap=cmap)
    fig.colorbar(im, ax=ax, label=r"$\omega$ [1/time]", shrink=0.9)
    ax.set_title(title or _title(_N_of(data), "equirectangular map"))
    return fig


def plot_mhd(
    Theta: ArrayLike,
    W: ArrayLike,
    *,
    title: str | None = None,
    levels: int = 14,
) -> Figure:
    r"""A state of MHD on the sphere: the vorticity :math:`\omega`, and the current density
    :math:`j = \Delta\theta` with the magnetic field lines (level lines of :math:`\theta`),
    on two latitude–longitude maps.

    ``Theta``, ``W``: the magnetic potential and the (relative) vorticity as matrices
    ``(N, N)`` (complex) or real coefficients (the fields of a state of
    :func:`isoflow.models.mhd_sphere`, e.g. ``problem.algebra.split(y)``; subtract the
    Coriolis matrix from the second field on a rotating sphere).

    Parameters
    ----------
    Theta : array_like, shape (N, N) or (n_coefficients,)
        The magnetic potential :math:`\theta` of one state.
    W : array_like, shape (N, N) or (n_coefficients,)
        The (relative) vorticity :math:`\omega` of the same state.
    title : str, optional
        Title of the figure. Default: ``"MHD on the sphere, N = ..."`` (``N`` only when
        ``W`` is a matrix).
    levels : int
        Number of field lines (default 14; :func:`draw_field_lines`).

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    ShapeError
        ``Theta`` or ``W`` is not one field.
    """
    from matplotlib.figure import Figure

    from ._basis import degree_order

    ct = _coefficients(Theta)
    cw = _coefficients(W)
    if ct.ndim != 1 or cw.ndim != 1:
        raise ShapeError(f"plot_mhd: give one state, got shapes {ct.shape} and {cw.shape}")
    ls, _ = degree_order(lmax_of(ct.size, "plot_mhd"))
    fig = Figure(figsize=(12, 4.2), layout="constrained")
    axes = fig.subplots(1, 2)
    im = draw_map(axes[0], cw)
    fig.colorbar(im, ax=axes[0], label=r"$\omega$", shrink=0.85)
    axes[0].set_title(r"vorticity $\omega$")
    im = draw_map(axes[1], -ls * (ls + 1.0) * ct, cmap="PuOr_r")
    fig.colorbar(im, ax=axes[1], label=r"$j = \Delta\theta$", shrink=0.85)
    draw_field_lines(axes[1], ct, levels=levels)
    axes[1].set_title(r"current $j$ and field lines (levels of $\theta$)")
    N = _N_of(W)
    fig.suptitle(title or ("MHD on the sphere" + (f", N = {N}" if N else "")))
    return fig


def plot_orthographic(
    data: ArrayLike,
    *,
    centers: Sequence[tuple[float, float]] = ((30.0, 0.0), (30.0, 180.0)),
    title: str | None = None,
    vmax: float | None = None,
    cmap: str = _CMAP,
    resolution: int = 200,
) -> Figure:
    """The vorticity seen from one or more viewpoints ``(latitude, longitude)`` [deg].

    Parameters
    ----------
    data : array_like, shape (N, N) or (n_coefficients,)
        One vorticity field: a matrix (complex) or real coefficients.
    centers : sequence of (float, float)
        The viewpoints ``(latitude, longitude)`` in degrees, one panel each (at least one;
        default ``((30, 0), (30, 180))``); latitudes in ``[-90, 90]``.
    title : str, optional
        Title of the figure. Default: ``"vorticity ω, N = ..., orthographic views"`` (``N``
        only when ``data`` is a matrix).
    vmax : float, optional
        Colour limit (positive), shared by the panels. Default: the largest ``|omega|`` on
        the grid of :func:`draw_map`'s default resolution.
    cmap : str
        Name of a matplotlib colour map (default ``"RdBu_r"``).
    resolution : int
        Pixels across each disk (at least 3, default 200).

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    ShapeError
        ``data`` is not one field.
    ParameterError
        A bad or empty ``centers``, a bad ``resolution`` or ``vmax``.
    """
    from matplotlib.figure import Figure

    c = _coefficients(data)
    if c.ndim != 1:
        raise ShapeError(f"plot_orthographic: give one vorticity field, got shape {c.shape}")
    if isinstance(centers, str) or not isinstance(centers, Sequence | np.ndarray):
        raise ParameterError(
            f"plot_orthographic: centers is a list of (latitude, longitude), got {centers!r}"
        )
    centers = [_center(ctr, "plot_orthographic") for ctr in centers]
    if not centers:
        raise ParameterError("plot_orthographic: give at least one center")
    check_N(resolution, "plot_orthographic: resolution", minimum=3)
    lim = _vmax(vmax, "plot_orthographic")
    if lim is None:
        lim = float(np.max(np.abs(synthesize(c, *default_grid_shape(lmax_of(c.size, "c"))))))
    fig = Figure(figsize=(3.6 * len(centers) + 0.8, 3.9), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, len(centers)))
    im: Any = None
    for ax, ctr in zip(axes, centers, strict=True):
        im = draw_orthographic(ax, c, center=ctr, vmax=lim, cmap=cmap, resolution=resolution)
        ax.set_title(f"view from lat {ctr[0]:g}°, lon {ctr[1]:g}°", fontsize=9)
    fig.colorbar(im, ax=list(axes), label=r"$\omega$ [1/time]", shrink=0.85)
    fig.suptitle(title or _title(_N_of(data), "orthographic views"))
    return fig


#: Spectrum values below this fraction of the largest are zero up to the rounding of the
#: transforms (degrees the data do not have); they are left out of spectrum plots.
SPECTRUM_FLOOR = 1e-14


def draw_energy_spectrum(
    ax: Axes,
    spectra: Mapping[str, ArrayLike],
    *,
    reference_slopes: Sequence[float] = (),
    ylabel: str | None = None,
) -> None:
    r"""Draw log–log energy spectra :math:`E_l` against degree ``l`` into ``ax``.

    ``spectra`` maps a label to a spectrum ``(lmax,)`` (degrees ``1..lmax``) or a vorticity
    matrix ``(N, N)`` (complex; its spectrum is computed). Values below
    :data:`SPECTRUM_FLOOR` times the largest are left out, and the vertical axis spans the
    values drawn (with a margin), not the rounding level below them.
    ``reference_slopes`` adds dashed power laws :math:`l^{s}` through the largest value;
    ``ylabel`` replaces the kinetic spectrum's axis label.

    Raises
    ------
    ShapeError
        A spectrum that is not one vector (or one matrix), or an empty one.
    NonFiniteError
        A spectrum with NaN or Inf.
    """
    curves = [(label, _spectrum(label, d)) for label, d in spectra.items()]
    if not curves:
        raise ShapeError("draw_energy_spectrum: give at least one spectrum")
    top = max(float(np.max(E)) for _, E in curves)
    shown = []
    for label, E in curves:
        keep = E > SPECTRUM_FLOOR * top if top > 0 else np.zeros(E.shape, dtype=bool)
        ax.loglog(np.arange(1, E.size + 1), np.where(keep, E, np.nan), label=label)
        shown.append(E[keep])
    values = np.concatenate(shown)
    if values.size:
        lmax = max(E.size for _, E in curves)
        ls = np.arange(1, lmax + 1)
        for s in reference_slopes:
            ax.loglog(ls, top * ls**s, "k--", lw=0.7, label=f"$l^{{{s:g}}}$")
        ax.set_ylim(float(np.min(values)) / 3, top * 3)
    ax.set_xlabel("degree $l$")
    ax.set_ylabel(ylabel or r"$E_l = \sum_m \omega_{lm}^2 / (l(l+1))$")
    ax.legend(fontsize=8)


def _spectrum(label: str, data: ArrayLike) -> Array:
    """The energy spectrum ``(lmax,)`` of ``data``: a spectrum itself or a vorticity matrix."""
    from ._diagnostics import energy_spectrum

    arr = np.asarray(data)
    if np.iscomplexobj(arr):
        if arr.ndim != 2 or arr.shape[0] != arr.shape[1]:
            raise ShapeError(
                f"spectrum {label!r}: a vorticity matrix must have shape (N, N), got {arr.shape}"
            )
        E = np.asarray(energy_spectrum(arr), dtype=float)
    elif arr.dtype.kind not in "iuf" or arr.ndim != 1 or arr.size == 0:
        raise ShapeError(
            f"spectrum {label!r}: give E_l for l = 1..lmax as a non-empty real vector, got "
            f"shape {arr.shape} of dtype {arr.dtype}"
        )
    else:
        E = arr.astype(float)
    if not np.all(np.isfinite(E)):  # it would blank every curve of the axes (their scale)
        raise NonFiniteError(f"spectrum {label!r} must be finite (found NaN or Inf)")
    return E


def plot_energy_spectrum(
    spectra: Mapping[str, ArrayLike],
    *,
    title: str | None = None,
    reference_slopes: Sequence[float] = (-3.0,),
    ylabel: str | None = None,
) -> Figure:
    r"""Log–log energy spectra :math:`E_l` against degree ``l`` (:func:`draw_energy_spectrum`).

    ``spectra`` maps a label (e.g. ``"t = 0"``) to either a spectrum ``(lmax,)`` (degrees
    ``1..lmax``) or a vorticity matrix ``(N, N)`` (complex; its spectrum is computed).
    ``reference_slopes`` draws dashed power laws :math:`l^{s}` for orientation. ``ylabel``
    replaces the kinetic spectrum's label (e.g. for magnetic spectra,
    :func:`~isoflow.sphere.magnetic_energy_spectrum`, drawn next to kinetic ones).

    Parameters
    ----------
    spectra : mapping of str to array_like
        Label to spectrum ``(lmax,)`` or vorticity matrix ``(N, N)``, one curve each.
    title : str, optional
        Title of the axes (default ``"energy spectrum"``).
    reference_slopes : sequence of float
        Exponents ``s`` of the dashed power laws (default ``(-3.0,)``; ``()`` for none).
    ylabel : str, optional
        Label of the vertical axis (default: the kinetic spectrum's formula).

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    ShapeError
        No spectrum, or one that is not a vector or a square matrix.
    NonFiniteError
        A spectrum with NaN or Inf.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(6, 4.5), layout="constrained")
    ax = fig.subplots()
    draw_energy_spectrum(ax, spectra, reference_slopes=reference_slopes, ylabel=ylabel)
    ax.set_title(title or "energy spectrum")
    return fig


def plot_invariants(
    ts: ArrayLike,
    *,
    casimirs: ArrayLike | None = None,
    energy: ArrayLike | None = None,
    enstrophy: ArrayLike | None = None,
    title: str | None = None,
) -> Figure:
    r"""Relative variation of the invariants against time (log scale).

    ``casimirs`` ``(n_t, K)`` (e.g. :func:`isoflow.sphere.casimirs`, ``k = 2..K+1``),
    ``energy`` and ``enstrophy`` ``(n_t,)``: each curve is :math:`|I(t) - I(0)| / |I(0)|`
    (Casimirs of odd order, which may vanish initially, relative to
    :math:`\max_t |C_k|` instead).

    Parameters
    ----------
    ts : array_like, shape (n_t,)
        The times (finite, at least one).
    casimirs : array_like, shape (n_t, K), optional
        Casimirs ``C_2, ..., C_{K+1}`` at each time, drawn in the upper panel.
    energy, enstrophy : array_like, shape (n_t,), optional
        Energy and enstrophy at each time, drawn in the lower panel.
    title : str, optional
        Title of the figure (default ``"invariants against time"``).

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    ShapeError
        A series of the wrong shape (not one value, or one row, per time).
    NonFiniteError
        A series with NaN or Inf.
    ParameterError
        A series that is not real.
    """
    from matplotlib.figure import Figure

    t = _series(ts, None, "plot_invariants: ts")
    if casimirs is not None:
        C = np.asarray(casimirs)
        if C.ndim != 2 or C.shape[0] != t.size or C.shape[1] == 0:
            raise ShapeError(
                f"plot_invariants: casimirs must have shape ({t.size}, K), one row per time, "
                f"got {C.shape}"
            )
        C = np.stack([_series(col, t.size, "plot_invariants: casimirs") for col in C.T], axis=1)
    energy = None if energy is None else _series(energy, t.size, "plot_invariants: energy")
    enstrophy = (
        None if enstrophy is None else _series(enstrophy, t.size, "plot_invariants: enstrophy")
    )
    fig = Figure(figsize=(7, 5), layout="constrained")
    axes = fig.subplots(2, 1, sharex=True)
    floor = 1e-18
    if casimirs is not None:
        for j in range(C.shape[1]):
            ref = abs(C[0, j]) if j % 2 == 0 else float(np.max(np.abs(C[:, j])))
            ref = ref if ref > 0 else 1.0
            axes[0].semilogy(t, np.maximum(np.abs(C[:, j] - C[0, j]) / ref, floor),
                             lw=0.8, label=f"$C_{{{j + 2}}}$")  # fmt: skip
        axes[0].legend(fontsize=8, ncol=C.shape[1])
    axes[0].set_ylabel("relative variation")
    axes[0].set_title(r"Casimirs $C_k = \frac{4\pi}{N}\mathrm{Tr}((-iW)^k)$")
    for name, series, color in (("energy $H$", energy, "C3"), ("enstrophy", enstrophy, "C2")):
        if series is None:
            continue
        s = np.asarray(series, dtype=float)
        ref = abs(s[0]) if s[0] != 0 else 1.0
        axes[1].semilogy(t, np.maximum(np.abs(s - s[0]) / ref, floor), lw=0.8, color=color,
                         label=name)  # fmt: skip
    axes[1].set_ylabel("relative variation")
    axes[1].set_xlabel("time $t$")
    axes[1].set_title("energy and enstrophy")
    if energy is not None or enstrophy is not None:
        axes[1].legend(fontsize=8)
    fig.suptitle(title or "invariants against time")
    return fig


def animate(
    states: ArrayLike,
    path: str | os.PathLike[str],
    *,
    ts: ArrayLike | None = None,
    kind: str = "map",
    center: tuple[float, float] = (30.0, 0.0),
    fps: int = 10,
    vmax: float | None = None,
    title: str | None = None,
    dpi: float = 80,
) -> Path:
    """Write a movie of a sequence of vorticity states.

    Parameters
    ----------
    states : array_like, shape (n_frames, N, N) or (n_frames, n_coefficients)
        Matrices (complex) or real coefficients.
    path : path
        ``.gif`` (matplotlib's Pillow writer, always available) or ``.mp4`` (needs an
        ``ffmpeg`` executable; without one a :class:`~isoflow.ParameterError` says so).
    ts : array_like, optional
        Times of the frames, shown in the title.
    kind : {"map", "orthographic"}
    center : (latitude, longitude) in degrees, for ``kind="orthographic"``.
    fps : int
        Frames per second (a positive integer).
    vmax : float, optional
        Colour limit (default: the largest ``|omega|`` over all frames, fixed for the movie).
    title : str, optional
        Title of every frame (followed by the frame's time).
    dpi : float
        Resolution of the frames in dots per inch (positive).

    Returns
    -------
    Path

    Raises
    ------
    ParameterError
        A bad path suffix, ``kind``, ``center``, ``fps``, ``dpi`` or ``vmax``, or ``.mp4``
        without ffmpeg.
    ShapeError
        Not a sequence of states, or ``ts`` not one finite time per state.
    """
    from matplotlib import animation
    from matplotlib.figure import Figure

    p = Path(path)
    suffix = p.suffix.lower()
    if suffix not in (".gif", ".mp4"):
        raise ParameterError(f"animate: write a .gif or .mp4 file, got {p.name!r}")
    if kind not in ("map", "orthographic"):
        raise ParameterError(f"animate: kind must be 'map' or 'orthographic', got {kind!r}")
    if suffix == ".mp4" and not animation.writers.is_available("ffmpeg"):
        raise ParameterError(
            "animate: writing .mp4 needs the ffmpeg program, which was not found; "
            "write a .gif (Pillow) instead, or install ffmpeg"
        )
    rate = check_N(fps, "animate: fps", minimum=1)
    dots = _positive(dpi, "animate: dpi")
    center = _center(center, "animate")
    vmax = _vmax(vmax, "animate")
    c = _coefficients(states)
    if c.ndim != 2 or c.shape[0] < 1:
        raise ShapeError(f"animate: expected a sequence of states, got coefficients {c.shape}")
    n = c.shape[0]
    times = None if ts is None else _series(ts, n, "animate: ts")
    lmax = lmax_of(c.shape[-1], "animate")
    if vmax is None:
        vmax = float(np.max(np.abs(synthesize(c, *default_grid_shape(lmax)))))
    fig = Figure(figsize=(7.5, 4.0) if kind == "map" else (5.0, 5.0), layout="constrained")
    ax = fig.subplots()
    head = title or "vorticity"

    def draw(k: int) -> None:
        ax.clear()
        if kind == "map":
            draw_map(ax, c[k], vmax=vmax)
        else:
            draw_orthographic(ax, c[k], center=center, vmax=vmax)
        ax.set_title(head + ("" if times is None else f", t = {times[k]:.4g}"))

    writer: Any
    if suffix == ".gif":
        writer = animation.PillowWriter(fps=rate)
    else:
        writer = animation.FFMpegWriter(fps=rate)
    draw(0)
    fig.colorbar(ax.images[0], ax=ax, label=r"$\omega$", shrink=0.85)
    with writer.saving(fig, str(p), dots):
        for k in range(n):
            draw(k)
            writer.grab_frame()
    return p
