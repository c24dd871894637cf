r"""Zeitlin's quantization of functions on the sphere: the tools of the Euler model.

``iso.sphere`` holds the matrix side of the quantized Euler equations
(:func:`isoflow.models.euler_sphere`): the Hoppe–Yau Laplacian and its inverse in ``O(N^2)``,
the quantized spherical harmonics, coefficients <-> matrices <-> values on the sphere,
initial data, diagnostics and figures. Importing it loads neither numba, ducc0 nor
matplotlib; the compiled kernels are in :mod:`isoflow.sphere.compiled`.

Conventions (each checked by a test against an independent computation)
-----------------------------------------------------------------------
*Spin matrices.* :math:`s = (N-1)/2`, basis :math:`|m\rangle`, :math:`m = -s..s`; row and
column ``a = 0..N-1`` is :math:`m_a = a - s`. :math:`J_3 = \operatorname{diag}(m_a)`,
:math:`(J_+)_{a+1,a} = \sqrt{(a+1)(N-a-1)}`, :math:`J_\pm = J_1 \pm iJ_2`,
:math:`[J_1, J_2] = iJ_3`. :math:`S_a = iJ_a \in \mathfrak{su}(N)`.

*Coordinates and bracket.* :math:`\hbar = 2/\sqrt{N^2-1}`, :math:`X_a = \hbar J_a` quantize
the Cartesian coordinates :math:`x, y, z` of the unit sphere (:math:`\sum X_a^2 = I`), and
:math:`\frac{1}{i\hbar}[F, G]` quantizes the Poisson bracket :math:`\{f, g\} =
\frac1{\sin\theta}(f_\theta g_\varphi - f_\varphi g_\theta)` (:math:`\{x, y\} = z`).
The north pole :math:`z = 1` is the last row/column, :math:`m = s`.

*Laplacian.* :math:`\Delta_N W = \sum_a [S_a,[S_a,W]]`, eigenvalues :math:`-l(l+1)`,
``l = 0..N-1``, multiplicity ``2l + 1``; a symmetric tridiagonal matrix on each diagonal
(:func:`laplacian_block`).

*Quantized harmonics.* :math:`T_{lm}` (complex, ``|m| <= l <= N - 1``) is the eigenvector of
:math:`\Delta_N` for :math:`-l(l+1)` supported on diagonal ``m`` (entries
:math:`(a+m, a)`; ``m < 0`` above the main diagonal), the counterpart of the orthonormal
complex :math:`Y_{lm}` with the Condon–Shortley phase:

* normalization :math:`\frac{4\pi}{N}\operatorname{Tr}(T_{lm}^\dagger T_{l'm'}) =
  \delta_{ll'}\delta_{mm'}` (the quantized :math:`\int \bar Y Y' dA = \delta`; the trace
  pairing :math:`\frac{4\pi}{N}\operatorname{Tr}` quantizes :math:`\int_{S^2} dA`);
* phases: :math:`(T_{l0})_{N-1,N-1} > 0` (:math:`Y_{l0} > 0` at the north pole) and
  :math:`[J_\pm, T_{lm}] = \sqrt{(l\mp m)(l\pm m+1)}\,T_{l,m\pm1}` (the ladder of
  :math:`L_\pm Y_{lm}`, with :math:`\operatorname{ad}_{J_a}` the quantized angular momentum
  :math:`L_a = -i(r\times\nabla)_a`), :math:`T_{l,-m} = (-1)^m T_{lm}^\dagger`.

With these, :math:`T_{10} = \sqrt{3/4\pi}\,X_3` exactly (:math:`Y_{10} = \sqrt{3/4\pi}\,z`),
and :math:`T_{11} = -\sqrt{3/8\pi}\,\hbar J_+` (:math:`Y_{11} = -\sqrt{3/8\pi}(x+iy)`).

*Real harmonics and coefficients.* The real orthonormal harmonics
:math:`Y^{\mathrm{r}}_{lm} = \sqrt2\,(-1)^m\operatorname{Re}Y_{lm}` (``m > 0``),
:math:`Y_{l0}`, :math:`\sqrt2\,(-1)^m\operatorname{Im}Y_{l|m|}` (``m < 0``), e.g.
:math:`Y^{\mathrm r}_{11}, Y^{\mathrm r}_{1,-1}, Y^{\mathrm r}_{10} = \sqrt{3/4\pi}\,(x, y,
z)` (no Condon–Shortley sign left: the geodesy convention, orthonormal on the unit sphere).
A vorticity :math:`\omega = \sum_{l\ge1}\omega_{lm}Y^{\mathrm r}_{lm}` is the matrix

.. math::

    W = i\sum_{l=1}^{N-1}\sum_{m=-l}^{l}\omega_{lm}\,T^{\mathrm r}_{lm} \in \mathfrak{su}(N),

:math:`T^{\mathrm r}_{lm}` Hermitian, built from :math:`T_{lm}` like
:math:`Y^{\mathrm r}_{lm}` from :math:`Y_{lm}` (:func:`basis_matrix`). Coefficients are
stored flat, :math:`l^2 - 1 + l + m` (:func:`lm_index`), ``N^2 - 1`` of them for ``su(N)``.
:func:`from_coefficients` and :func:`to_coefficients` work diagonal by diagonal; the
basis is recomputed on each call (``eigh_tridiagonal`` per diagonal, ``O(N^3)`` time,
``O(N^2)`` memory: nothing of size ``N^3`` is stored).

*Time.* :math:`\dot W = \frac1\hbar[P, W]`, :math:`\Delta_N P = W`, is
:math:`\dot\omega = \{\omega, \psi\} = -u\cdot\nabla\omega`, :math:`\Delta\psi = \omega`,
:math:`u = n\times\nabla\psi` (outward normal ``n``): the continuum Euler equations with the
same time.

Contents
--------
Operators: :func:`hbar`, :func:`spin_matrices`, :func:`laplacian_block`,
:func:`laplacian_coefficients`, :func:`laplacian`, :func:`solve_poisson`.
Harmonics: :func:`diagonal_bases`, :func:`basis_matrix`, :func:`from_coefficients`,
:func:`to_coefficients`, :func:`lm_index`, :func:`degree_order`, :func:`coefficient_count`.
Grids (``ducc0``): :func:`grid`, :func:`synthesize`, :func:`analyze`, :func:`evaluate`,
:func:`from_function`, :func:`to_grid`.
Initial data: :func:`random_coefficients`, :func:`random_vorticity`,
:func:`vorticity_from_function`.
Dissipation and forcing: :class:`SphereDissipation`, :func:`degree_rates`,
:func:`band_forcing`, :func:`band_modes`.
Diagnostics: :func:`casimirs`, :func:`vorticity_levels`, :func:`energy`, :func:`enstrophy`,
:func:`energy_spectrum`, :func:`enstrophy_spectrum`, :func:`angular_momentum`.
Two fields (magnetohydrodynamics, :func:`isoflow.models.mhd_sphere`): :func:`current`,
:func:`magnetic_energy`, :func:`magnetic_energy_spectrum`, :func:`cross_casimirs`.
Figures (matplotlib): :func:`plot_map`, :func:`plot_orthographic`,
:func:`plot_energy_spectrum`, :func:`plot_invariants`, :func:`animate`; for two fields
:func:`plot_mhd` and :func:`draw_field_lines`.
"""

from __future__ import annotations

from typing import Any

from numpy.typing import ArrayLike, NDArray

from ._basis import basis_matrix as basis_matrix
from ._basis import coefficient_count as coefficient_count
from ._basis import degree_order as degree_order
from ._basis import diagonal_bases as diagonal_bases
from ._basis import from_coefficients as from_coefficients
from ._basis import lm_index as lm_index
from ._basis import to_coefficients as to_coefficients
from ._diagnostics import angular_momentum as angular_momentum
from ._diagnostics import casimirs as casimirs
from ._diagnostics import energy as energy
from ._diagnostics import energy_spectrum as energy_spectrum
from ._diagnostics import enstrophy as enstrophy
from ._diagnostics import enstrophy_spectrum as enstrophy_spectrum
from ._diagnostics import vorticity_levels as vorticity_levels
from ._dissipation import SphereDissipation as SphereDissipation
from ._dissipation import band_forcing as band_forcing
from ._dissipation import band_modes as band_modes
from ._dissipation import degree_rates as degree_rates
from ._grid import GEOMETRIES as GEOMETRIES
from ._grid import analyze as analyze
from ._grid import evaluate as evaluate
from ._grid import from_function as from_function
from ._grid import grid as grid
from ._grid import synthesize as synthesize
from ._initial import random_coefficients as random_coefficients
from ._initial import random_vorticity as random_vorticity
from ._initial import vorticity_from_function as vorticity_from_function
from ._mhd import cross_casimirs as cross_casimirs
from ._mhd import current as current
from ._mhd import magnetic_energy as magnetic_energy
from ._mhd import magnetic_energy_spectrum as magnetic_energy_spectrum
from ._operators import LaplacianCoefficients as LaplacianCoefficients
from ._operators import hbar as hbar
from ._operators import laplacian as laplacian
from ._operators import laplacian_block as laplacian_block
from ._operators import laplacian_coefficients as laplacian_coefficients
from ._operators import solve_poisson as solve_poisson
from ._operators import spin_matrices as spin_matrices
from .figures import animate as animate
from .figures import draw_field_lines as draw_field_lines
from .figures import plot_energy_spectrum as plot_energy_spectrum
from .figures import plot_invariants as plot_invariants
from .figures import plot_map as plot_map
from .figures import plot_mhd as plot_mhd
from .figures import plot_orthographic as plot_orthographic

__all__ = [
    "GEOMETRIES",
    "LaplacianCoefficients",
    "SphereDissipation",
    "analyze",
    "angular_momentum",
    "animate",
    "band_forcing",
    "band_modes",
    "basis_matrix",
    "casimirs",
    "coefficient_count",
    "cross_casimirs",
    "current",
    "degree_order",
    "degree_rates",
    "diagonal_bases",
    "draw_field_lines",
    "energy",
    "energy_spectrum",
    "enstrophy",
    "enstrophy_spectrum",
    "evaluate",
    "from_coefficients",
    "from_function",
    "grid",
    "hbar",
    "laplacian",
    "laplacian_block",
    "laplacian_coefficients",
    "lm_index",
    "magnetic_energy",
    "magnetic_energy_spectrum",
    "plot_energy_spectrum",
    "plot_invariants",
    "plot_map",
    "plot_mhd",
    "plot_orthographic",
    "random_coefficients",
    "random_vorticity",
    "solve_poisson",
    "spin_matrices",
    "synthesize",
    "to_coefficients",
    "to_grid",
    "vorticity_from_function",
    "vorticity_levels",
]


def to_grid(
    W: ArrayLike,
    ntheta: int | None = None,
    nphi: int | None = None,
    *,
    geometry: str = "CC",
    lmax: int | None = None,
) -> NDArray[Any]:
    r"""Values of the vorticity :math:`\omega` of matrices ``W`` on a ``ducc0`` grid.

    ``to_coefficients`` then :func:`synthesize`: ``W`` of shape ``(*batch, N, N)`` gives
    ``(*batch, ntheta, nphi)`` (default grid: :func:`~isoflow.sphere._grid.default_grid_shape`
    of degree ``lmax``, default ``N - 1``). The coefficient transform is done once for the
    whole batch.

    Parameters
    ----------
    W : array_like, shape (*batch, N, N)
        Vorticity matrices in ``su(N)`` (complex).
    ntheta, nphi : int, optional
        Number of rings in latitude and of points in longitude (default
        ``(2 lmax + 2, 4 lmax + 4)``; see :func:`~isoflow.sphere.synthesize`).
    geometry : {"CC", "GL", "F1"}
        The grid: Clenshaw–Curtis (default; equiangular, both poles included),
        Gauss–Legendre, or Fejér's first rule (equiangular, no poles); see
        :func:`~isoflow.sphere.grid`.
    lmax : int, optional
        Highest degree kept (default ``N - 1``).

    Returns
    -------
    ndarray, shape (*batch, ntheta, nphi)
        The real values of :math:`\omega`, rings from north to south.
    """
    return synthesize(to_coefficients(W, lmax), ntheta, nphi, geometry=geometry)
