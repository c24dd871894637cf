r"""Zeitlin's magnetohydrodynamics on the (rotating) sphere: two matrices, one structure.

Continuum model: incompressible ideal MHD on the unit sphere in terms of the vorticity
:math:`\omega = \Delta\psi` and the magnetic potential :math:`\theta` (velocity
:math:`u = n\times\nabla\psi`, magnetic field :math:`b = n\times\nabla\theta`, current
:math:`j = \Delta\theta`), with the bracket and orientation of
:func:`~isoflow.models.euler_sphere` (:math:`\{f, \psi\} = -u\cdot\nabla f`):

.. math::

    \dot\omega = \{\omega + f, \psi\} + \{\theta, j\}, \qquad \dot\theta = \{\theta, \psi\},

i.e. :math:`\dot\omega + u\cdot\nabla(\omega + f) = b\cdot\nabla j` (the curl of the Lorentz
force) and :math:`\dot\theta + u\cdot\nabla\theta = 0` (the potential is carried by the flow),
:math:`f = 2\Omega\cos\vartheta` the Coriolis parameter. Quantized as the Euler model
(:math:`W = i\,T(\omega)`, :math:`\Theta = i\,T(\theta)`, :math:`\{\cdot,\cdot\}\to
\frac1\hbar[\cdot,\cdot]`, :math:`\Delta\to\Delta_N`), with the absolute vorticity
:math:`Q = W + F`:

.. math::

    \dot\Theta = [B_0, \Theta], \qquad \dot Q = [B_0, Q] + [B_1, \Theta], \qquad
    B_0 = \frac1\hbar\Delta_N^{-1}Q + i\Omega J_3 = \frac{P}{\hbar}, \quad
    B_1 = \frac{J}{\hbar} = \frac1\hbar\Delta_N\Theta,

the isospectral flow of the dual-number pairs :math:`(\Theta, Q)` of
:func:`~isoflow.algebras.semidirect` over :math:`\mathfrak{su}(N)` with :math:`B = (B_0, B_1)`
(``docs/theory/semidirect.rst``). The Casimirs :math:`\operatorname{Tr}(\Theta^k)` and
:math:`\operatorname{Tr}(Q\Theta^k)` (the integrals of :math:`\theta^k` and of
:math:`(\omega + f)\theta^k`) are kept by IsoMP to rounding, the angular momentum too; the
energy :math:`H = E_K + E_M` (kinetic and magnetic) oscillates boundedly. With
:math:`\Theta = 0` the model is :func:`~isoflow.models.euler_sphere`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import sphere
from .._errors import ParameterError
from ..algebras import semidirect, su
from ..kernels import CompiledB
from ..problems import IsospectralProblem
from ..sphere import degree_order, from_coefficients, hbar, laplacian_coefficients
from ..sphere._operators import check_N
from ._euler_sphere import coriolis_matrix

__all__ = ["mhd_sphere"]

Array = NDArray[Any]


def _energy_parameter(v: Any, what: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
        raise ParameterError(f"mhd_sphere: {what} must be a real number, got {v!r}")
    if not (np.isfinite(v) and v >= 0):
        raise ParameterError(f"mhd_sphere: {what} must be finite and >= 0, got {v!r}")
    return float(v)


def _random_field(
    lmax: int, lmin: int, slope: float | None, energy_: float, rng: np.random.Generator
) -> Array:
    r"""Coefficients :math:`c_{lm}` of a random field (:func:`~isoflow.sphere.random_coefficients`)
    scaled to :math:`\frac12\sum c_{lm}^2/(l(l+1))` = ``energy_``: the vorticity for the
    kinetic energy, the current for the magnetic energy."""
    c = sphere.random_coefficients(lmax, lmin=lmin, slope=slope, seed=rng)
    ls, _ = degree_order(lmax)
    e = 0.5 * float(np.sum(c * c / (ls * (ls + 1.0))))
    return c * np.sqrt(energy_ / e)


def mhd_sphere(
    N: int = 128,
    omega: float = 0.0,
    seed: int = 0,
    *,
    lmin: int = 1,
    lmax: int | None = None,
    slope: float | None = None,
    kinetic_energy: float = 0.25,
    magnetic_energy: float = 0.25,
    W0: ArrayLike | None = None,
    Theta0: ArrayLike | None = None,
) -> tuple[IsospectralProblem, Array]:
    r"""Zeitlin's MHD on the sphere (module docstring) and its initial pair ``(Theta0, Q0)``.

    Parameters
    ----------
    N : int
        Matrix size, ``N >= 2``; resolves degrees ``l <= N - 1``.
    omega : float
        Angular velocity :math:`\Omega` of the sphere (default 0).
    seed : int
        Seed of the random initial data (the vorticity and the current are drawn from one
        generator, in that order).
    lmin, lmax : int
        Band of the random initial data (``lmax`` default ``min(10, N - 1)``).
    slope : float or None
        Expected spectra :math:`E_l \propto l^{\mathrm{slope}}` of the random vorticity and
        current (kinetic and magnetic energy spectra); ``None``: white coefficients.
    kinetic_energy, magnetic_energy : float
        The initial energies :math:`E_K = \frac12\sum\omega_{lm}^2/(l(l+1))` and
        :math:`E_M = \frac12\sum l(l+1)\theta_{lm}^2` of the random data, exactly (``>= 0``;
        ``magnetic_energy = 0`` gives :math:`\Theta = 0`, the Euler equations).
    W0, Theta0 : array_like, optional
        The initial relative vorticity and magnetic potential as matrices ``(*batch, N, N)``
        in ``su(N)`` instead of random data (one of them alone: the other is zero).

    Returns
    -------
    problem : IsospectralProblem
        On ``semidirect(su(N))`` with the compiled kernel
        ``CompiledB(isoflow.sphere.compiled.mhd_field, ...)``, ``hamiltonian``
        :math:`E_K + E_M`, ``invariants``: ``"theta_casimirs"``
        (:math:`\int\theta^k dA`, ``k = 2..6``), ``"cross_casimirs"``
        (:math:`\int(\omega + f)\,\theta^k dA`, ``k = 1..5``), ``"angular_momentum"``
        (``(3,)``; ``"angular_momentum_z"`` on a rotating sphere), and ``parameters``.
    y0 : ndarray, shape (*batch, 2, N, N)
        The pair :math:`(\Theta_0, W_0 + F)`.

    Raises
    ------
    ParameterError
        Bad ``N``, ``omega``, ``seed``, energies or band.
    ShapeError
        ``W0`` and ``Theta0`` of different or wrong shapes.
    NotInSpaceError
        ``W0`` or ``Theta0`` not in ``su(N)`` (the message names the field).

    References
    ----------
    V. Zeitlin, Finite-mode analogues of 2D ideal hydrodynamics..., Physica D 49 (1991) 353–362
    (MHD in Sec. 4). K. Modin, M. Roop, Spatio-temporal Lie–Poisson discretization for
    incompressible magnetohydrodynamics on the sphere, IMA J. Numer. Anal. (2025),
    arXiv:2311.16045.

    Examples
    --------
    >>> import isoflow as iso
    >>> prob, y0 = iso.models.mhd_sphere(N=12, seed=1)
    >>> sol = iso.solve(prob, iso.IsoMP(), y0, dt=0.05, n_steps=40)
    >>> bool(sol.diagnostics.casimir_drift < 1e-12)
    True
    """
    N = check_N(N, "mhd_sphere: N")
    if isinstance(omega, bool) or not isinstance(omega, (int, float, np.integer, np.floating)):
        raise ParameterError(f"mhd_sphere: omega must be a real number, got {omega!r}")
    if not np.isfinite(omega):
        raise ParameterError(f"mhd_sphere: omega must be finite, got {omega!r}")
    Om = float(omega)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise ParameterError(f"mhd_sphere: seed must be an integer, got {seed!r}")
    e_kin = _energy_parameter(kinetic_energy, "kinetic_energy")
    e_mag = _energy_parameter(magnetic_energy, "magnetic_energy")
    lmax_ = min(10, N - 1) if lmax is None else check_N(lmax, "mhd_sphere: lmax", minimum=1)
    if lmax_ > N - 1:
        raise ParameterError(f"mhd_sphere: lmax must be <= N - 1 = {N - 1}, got {lmax_}")
    lmin_ = check_N(lmin, "mhd_sphere: lmin", minimum=1)
    if lmin_ > lmax_:
        raise ParameterError(f"mhd_sphere: need lmin <= lmax, got {lmin_} > {lmax_}")
    base = su(N)
    alg = semidirect(base)
    parameters: dict[str, Any] = {"N": N, "omega": Om, "hbar": hbar(N), "seed": int(seed)}
    if W0 is not None or Theta0 is not None:
        th = None if Theta0 is None else np.asarray(Theta0)
        w = None if W0 is None else np.asarray(W0)
        th = np.zeros_like(w) if th is None else th
        w = np.zeros_like(th) if w is None else w
        y = alg.validate(alg.pair(th, w), "the initial pair (Theta0, W0)")
        parameters["initial"] = "matrices"
    else:
        rng = np.random.default_rng(int(seed))
        c_w = _random_field(lmax_, lmin_, slope, e_kin, rng)
        c_j = _random_field(lmax_, lmin_, slope, e_mag, rng)
        ls, _ = degree_order(lmax_)
        y = alg.pair(from_coefficients(-c_j / (ls * (ls + 1.0)), N), from_coefficients(c_w, N))
        parameters.update(
            initial="random", lmin=lmin_, lmax=lmax_, slope=slope,
            kinetic_energy=e_kin, magnetic_energy=e_mag,
        )  # fmt: skip
    F = coriolis_matrix(N, Om)
    theta0, w0 = alg.split(y)
    y0 = alg.pair(theta0, w0 + F)

    coef = laplacian_coefficients(N)
    shift = 1j * Om * (np.arange(N) - 0.5 * (N - 1))  # F / (2 hbar), as euler_sphere
    from ..sphere.compiled import mhd_field

    kernel = CompiledB(
        mhd_field, (coef.inv_piv, coef.mult, coef.diag, coef.gamma, 1.0 / hbar(N), shift),
        name="mhd_sphere_field", raises=False,
    )  # fmt: skip

    def hamiltonian(Y: Array) -> Array:
        theta, q = alg.split(np.asarray(Y))
        return sphere.energy(q - F) + sphere.magnetic_energy(theta)

    def theta_casimirs(Y: Array) -> Array:
        return sphere.casimirs(alg.split(np.asarray(Y))[0])

    def cross(Y: Array) -> Array:
        theta, q = alg.split(np.asarray(Y))
        return sphere.cross_casimirs(theta, q)

    invariants: dict[str, Callable[[Array], Array]] = {
        "theta_casimirs": theta_casimirs,
        "cross_casimirs": cross,
    }

    def momentum(Y: Array) -> Array:
        return sphere.angular_momentum(alg.split(np.asarray(Y))[1] - F)

    if Om == 0.0:
        invariants["angular_momentum"] = momentum
    else:
        invariants["angular_momentum_z"] = lambda Y: momentum(Y)[..., 2]
    problem = IsospectralProblem(
        algebra=alg,
        kernel=kernel,
        hamiltonian=hamiltonian,
        invariants=invariants,
        name=f"MHD on the sphere, su({N}) x| su({N})*" + (f", Omega = {Om:g}" if Om else ""),
        parameters=parameters,
    )
    return problem, y0
