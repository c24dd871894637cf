r"""The shallow-water quasi-geostrophic model on the rotating sphere, Zeitlin-truncated.

Continuum model (Verkley 2009; Schubert et al. 2009): the potential vorticity

.. math::

    q = \Delta\psi - F\cos^2\theta\,\psi - \kappa^2\psi + 2\Omega\cos\theta, \qquad
    q_t = \{q, \psi\},

colatitude :math:`\theta` (so :math:`\cos\theta = z`), the Lamb parameter
:math:`F = 4\Omega^2 a^2/(gH)` (the squared ratio of the planet's radius to the polar
deformation radius) and, for the Helmholtz variant, a constant inverse deformation radius
:math:`\kappa` (the equivalent-barotropic model, ``deformation_radius = 1/kappa``). The bracket
and the time are those of :func:`isoflow.models.euler_sphere`; ``F = kappa = 0`` is Euler's
model. A Lie–Poisson system: every Casimir :math:`\int g(q)` is conserved, and so is the energy
:math:`E = \frac12\int(|\nabla\psi|^2 + (F z^2 + \kappa^2)\psi^2) = -\frac12\int\psi\,(q - f)`.

Zeitlin's truncation (Franken, Caliaro, Cifani and Geurts 2023): the potential vorticity becomes
:math:`Q = A\Psi + F_\Omega \in \mathfrak u(N)` with :math:`F_\Omega = 2i\Omega\hbar J_3` and

.. math::

    A\Psi = \Delta_N\Psi - \kappa^2\Psi - \tfrac F2\,(Z\Psi + \Psi Z), \qquad
    Z = T(z^2) = \tfrac13 I + \tfrac43\sqrt{\pi/5}\,T_{20},

the quantization of :math:`z^2` (diagonal, degrees 0 and 2) entering by the symmetrized
(Jordan) product, so that ``A`` is self-adjoint in the trace pairing and, like
:math:`\Delta_N`, tridiagonal on each diagonal of the matrix: entry ``(a, b)`` of
:math:`Z\Psi + \Psi Z` is :math:`(Z_{aa} + Z_{bb})\Psi_{ab}`. So the solve
:math:`A\Psi = Q - F_\Omega` is one tridiagonal solve per diagonal, ``O(N^2)``, compiled
(:func:`isoflow.sphere.compiled.qg_field`). For :math:`F > 0` or :math:`\kappa > 0` every block is
definite, the main diagonal's too: the mean of :math:`\psi` is not a gauge here (shifting
:math:`\psi` by a constant changes :math:`q` by :math:`-F z^2` times it); it is fixed by the
mean of :math:`q`, a Casimir. The model's states have zero mean potential vorticity (the
initial relative vorticity is in :math:`\mathfrak{su}(N)` and so is :math:`F_\Omega`), so the
state space is :math:`\mathfrak{su}(N)` as for Euler's model, and for ``F = kappa = 0`` the
model is :func:`~isoflow.models.euler_sphere`'s, bit for bit.

:math:`\dot Q = \frac1\hbar[\Psi, Q]`, i.e. ``B(Q) = Psi_0 / hbar`` with :math:`\Psi_0` the
traceless part of :math:`\Psi` (the trace commutes with everything); the field ignores the trace
of IsoMP's stage, as Euler's does, so that the step tends to Euler's as ``F -> 0``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._errors import ParameterError
from .._reductions import real_inner
from ..algebras import su
from ..kernels import CompiledB
from ..problems import IsospectralProblem
from ..sphere import (
    basis_matrix,
    enstrophy,
    hbar,
    laplacian_coefficients,
    to_coefficients,
)
from ..sphere._basis import blocked_rows_matmul
from ..sphere._operators import as_matrices, check_N, factor_diagonals
from ._checks import require_memory
from ._euler_sphere import coriolis_matrix, euler_sphere, initial_vorticity, real_parameter
from ._forced import budget_observables, sphere_split

__all__ = ["QGOperator", "qg_operator", "qg_sphere", "zonal_wind"]

Array = NDArray[Any]


class QGOperator:
    r"""The operator :math:`A = \Delta_N - \kappa^2 - \frac F2\{Z, \cdot\}` of ``qg_sphere`` and
    its per-diagonal factorization (``O(N^2)`` numbers).

    Attributes
    ----------
    N, lamb, kappa : int, float, float
    z2 : ndarray, shape (N,)
        The diagonal of :math:`Z = T(z^2)`.
    diag : ndarray, shape (N, N)
        The coefficient of :math:`\Psi_{ab}` in :math:`(A\Psi)_{ab}`.
    inv_piv, mult : ndarray, shape (N, N)
        The factorization (``isoflow.sphere._operators.factor_diagonals``).
    """

    def __init__(self, N: int, lamb: float, kappa: float) -> None:
        self.N, self.lamb, self.kappa = N, lamb, kappa
        self.z2 = quantized_z2(N)
        lap = laplacian_coefficients(N)
        self.gamma = lap.gamma
        self.diag = lap.diag - kappa**2 - 0.5 * lamb * (self.z2[:, None] + self.z2[None, :])
        inv_piv, mult = factor_diagonals(self.diag, lap.gamma)
        if not np.all(inv_piv < 0):  # every block of A must be negative definite
            raise ParameterError(
                f"qg_sphere: the operator Delta - kappa^2 - F z^2 is not negative definite for "
                f"N = {N}, F = {lamb}, kappa = {kappa} (a pivot of its factorization is >= 0)"
            )
        self.inv_piv, self.mult = inv_piv, mult

    def apply(self, P: ArrayLike) -> Array:
        r""":math:`A P` for matrices ``(*batch, N, N)`` (``O(N^2)`` each)."""
        from ..sphere import laplacian

        Pa = np.asarray(P, dtype=np.complex128)
        lap = laplacian(Pa)
        z = self.z2
        return lap - (self.kappa**2 + 0.5 * self.lamb * (z[:, None] + z[None, :])) * Pa

    def solve(self, W: ArrayLike) -> Array:
        r""":math:`A^{-1} W` for matrices ``(*batch, N, N)`` (``O(N^2)`` each, compiled)."""
        from ..sphere.compiled import helmholtz_solve_batch

        flat, batch, N = as_matrices(W, "qg_operator.solve")
        out = np.empty_like(flat)
        helmholtz_solve_batch(flat, out, self.inv_piv, self.mult, np.zeros(N, np.complex128))
        return out.reshape(*batch, N, N)


def quantized_z2(N: int) -> Array:
    r"""The diagonal of :math:`T(z^2) = \frac13 I + \frac43\sqrt{\pi/5}\,T_{20}` (``z = cos``
    colatitude), the Zeitlin quantization of :math:`z^2`; for ``N = 2`` (no degree 2) its
    projection :math:`\frac13 I`."""
    z2 = np.full(N, 1.0 / 3.0)
    if N >= 3:
        z2 = z2 + (4.0 / 3.0) * np.sqrt(np.pi / 5.0) * np.real(np.diag(basis_matrix(N, 2, 0)))
    return z2


def qg_operator(N: int, lamb: float = 0.0, kappa: float = 0.0) -> QGOperator:
    r"""The elliptic operator of :func:`qg_sphere` (checked: finite, ``lamb, kappa >= 0``).

    Parameters
    ----------
    N : int
        Matrix size.
    lamb : float
        :math:`F \ge 0`, the coefficient of the :math:`F\cos^2\theta\,\psi` term (default 0).
    kappa : float
        :math:`\kappa \ge 0`, the inverse deformation radius (default 0).

    Returns
    -------
    QGOperator

    Raises
    ------
    ParameterError
        A bad ``N``, a negative or non-finite ``lamb`` or ``kappa``, or an operator that is
        not negative definite.
    """
    N = check_N(N, "qg_sphere: N")
    lamb = _nonnegative(lamb, "lamb")
    kappa = _nonnegative(kappa, "kappa")
    return QGOperator(N, lamb, kappa)


def _nonnegative(v: Any, what: str) -> float:
    x = real_parameter(v, what, "qg_sphere")
    if x < 0:
        raise ParameterError(f"qg_sphere: {what} must be >= 0, got {v!r}")
    return x


def zonal_wind(P: ArrayLike, colatitudes: ArrayLike) -> Array:
    r"""The zonal-mean eastward wind :math:`\bar u(\theta) = \partial_\theta\bar\psi` of stream
    matrices ``P`` (``(*batch, N, N)``) at the colatitudes ``theta`` (radians).

    With :math:`u = n\times\nabla\psi` the eastward component is :math:`\partial_\theta\psi`;
    its zonal mean needs the ``m = 0`` coefficients only: :math:`\bar u = \sum_l \psi_{l0}\,
    \partial_\theta Y_{l0}`, :math:`\partial_\theta Y_{l0} = \sqrt{(2l+1)/(4\pi)}\,
    P_l^1(\cos\theta)` (``scipy.special.lpmv``, Condon–Shortley phase).
    """
    from scipy.special import lpmv

    Pa = np.asarray(P)
    N = Pa.shape[-1]
    theta = np.asarray(colatitudes, dtype=float)
    psi = to_coefficients(Pa)
    ls = np.arange(1, N)
    idx = ls * ls - 1 + ls  # lm_index(l, 0)
    dY = np.sqrt((2 * ls + 1) / (4 * np.pi))[:, None] * lpmv(1, ls[:, None], np.cos(theta))
    return blocked_rows_matmul(psi[..., idx], dY)  # a row's wind whatever the batch


def qg_sphere(
    N: int = 128,
    lamb: float = 0.0,
    omega: float = 0.0,
    initial: str | ArrayLike | Callable[[Array, Array], ArrayLike] = "random",
    seed: int = 0,
    *,
    deformation_radius: float | None = None,
    lmin: int = 1,
    lmax: int | None = None,
    slope: float | None = None,
    rms: float = 1.0,
    W0: ArrayLike | None = None,
    viscosity: float = 0.0,
    hyperviscosity: tuple[float, float] | None = None,
    drag: float = 0.0,
    forcing: Any = None,
    forcing_band: tuple[int, int] | None = None,
    energy_rate: float | None = None,
    forcing_seed: int | None = None,
) -> tuple[IsospectralProblem, Array]:
    r"""The shallow-water quasi-geostrophic model on the sphere and its initial state.

    Equations in the module docstring: :math:`\dot Q = [\Psi/\hbar, Q]` with
    :math:`A\Psi = Q - F_\Omega`, :math:`A = \Delta_N - \kappa^2 - \frac F2\{Z, \cdot\}`.

    Parameters
    ----------
    N : int
        Matrix size, ``N >= 2``.
    lamb : float
        The Lamb parameter :math:`F \ge 0` (``0``: Euler's model).
    omega : float
        The rotation :math:`\Omega` (the planetary vorticity :math:`2\Omega\cos\theta`).
    initial, seed, lmin, lmax, slope, rms, W0 :
        The initial *relative potential vorticity* :math:`q - 2\Omega\cos\theta`, as in
        :func:`~isoflow.models.euler_sphere`.
    deformation_radius : float or None
        The Helmholtz variant: :math:`\kappa = 1/L_d` (``None``: :math:`\kappa = 0`).
    viscosity, hyperviscosity, drag, forcing, forcing_band, energy_rate, forcing_seed :
        Dissipation and forcing of the relative potential vorticity, as in
        :func:`~isoflow.models.euler_sphere` (integrate with :class:`~isoflow.Strang`).

    Returns
    -------
    problem : IsospectralProblem
        On ``su(N)`` with the compiled kernel; the
        ``hamiltonian`` is the energy :math:`E = -\frac{2\pi}{N}\operatorname{Re}
        \operatorname{Tr}(\Psi^\dagger(Q - F_\Omega))`; ``invariants``: ``"enstrophy"``
        (an ``observable`` with dissipation or forcing, which change it); ``observables``
        (saved and drawn, no drift): ``"zonal_wind"`` (on :data:`ZONAL_LATITUDES`
        colatitudes, see :func:`zonal_wind`), the kinetic ``"energy_spectrum"``,
        ``"enstrophy_spectrum"``, ``"energy_transfer"`` and, with dissipation or forcing, the
        budgets (:mod:`isoflow.models._forced`). In the Euler limit (``F = kappa = 0``) the
        problem is :func:`~isoflow.models.euler_sphere`'s with ``"zonal_wind"`` added: its
        invariants (the enstrophy and the angular momentum) and observables (the spectra and
        the transfer only with dissipation or forcing) are Euler's.
    Q0 : ndarray, shape (*batch, N, N)

    Raises
    ------
    ParameterError
        A negative or non-finite ``lamb``, ``deformation_radius <= 0``, and those of
        :func:`~isoflow.models.euler_sphere`.

    References
    ----------
    W. T. M. Verkley, A balanced approximation of the one-layer shallow-water equations on a
    sphere, J. Atmos. Sci. 66 (2009) 1735–1748. W. H. Schubert, R. K. Taft, L. G. Silvers,
    Shallow water quasi-geostrophic theory on the sphere, J. Adv. Model. Earth Syst. 1 (2009) 2.
    A. Franken, M. Caliaro, P. Cifani, B. Geurts, Zeitlin truncation of a shallow water
    quasi-geostrophic model for planetary flow, J. Adv. Model. Earth Syst. (2024),
    arXiv:2306.15481.

    Examples
    --------
    >>> import isoflow as iso
    >>> prob, Q0 = iso.models.qg_sphere(N=16, lamb=10.0, omega=1.0, seed=1)
    >>> sol = iso.solve(prob, iso.IsoMP(), Q0, dt=0.05, n_steps=10)
    >>> bool(sol.diagnostics.casimir_drift < 1e-12)
    True
    """
    N = check_N(N, "qg_sphere: N")
    lamb_ = _nonnegative(lamb, "lamb")
    kappa = 0.0
    if deformation_radius is not None:
        Ld = real_parameter(deformation_radius, "deformation_radius", "qg_sphere")
        if Ld <= 0:
            raise ParameterError(f"qg_sphere: deformation_radius must be > 0, got {Ld!r}")
        kappa = 1.0 / Ld
    if lamb_ == 0.0 and kappa == 0.0:  # Euler's model, bit for bit
        return _as_qg(
            euler_sphere(
                N, omega, initial, seed, lmin=lmin, lmax=lmax, slope=slope, rms=rms, W0=W0,
                viscosity=viscosity, hyperviscosity=hyperviscosity, drag=drag, forcing=forcing,
                forcing_band=forcing_band, energy_rate=energy_rate, forcing_seed=forcing_seed,
            )
        )  # fmt: skip
    require_memory(16.0 * N * N, 8.0, f"qg_sphere: N = {N}")
    Om = real_parameter(omega, "omega", "qg_sphere")
    op = QGOperator(N, lamb_, kappa)
    alg = su(N)
    h = hbar(N)
    q_rel, kind, extra = initial_vorticity(
        N, initial, seed, lmin=lmin, lmax=lmax, slope=slope, rms=rms, W0=W0, model="qg_sphere"
    )
    F = coriolis_matrix(N, Om)
    Q0 = q_rel + F
    planetary = np.ascontiguousarray(np.diag(F))
    from ..sphere.compiled import qg_field

    kernel = CompiledB(
        qg_field, (op.inv_piv, op.mult, 1.0 / h, planetary), name="qg_field", raises=False
    )

    def energy_weight(E: Array) -> Array:
        r"""The QG energy of each unit harmonic ``E``: :math:`-\frac{4\pi}{N}\operatorname{Re}
        \langle E, A^{-1}E\rangle` (:math:`1/\lambda_l` as ``F, kappa -> 0``)."""
        return -(4.0 * np.pi / N) * real_inner(E, op.solve(E))

    split = sphere_split(
        N, viscosity=viscosity, hyperviscosity=hyperviscosity, drag=drag, forcing=forcing,
        planetary=F, model="qg_sphere", forcing_band=forcing_band, energy_rate=energy_rate,
        forcing_seed=forcing_seed, energy_weight=energy_weight,
    )  # fmt: skip

    def relative(Q: Array) -> Array:
        return np.asarray(Q) - F

    def stream(Q: Array) -> Array:
        return op.solve(relative(Q))

    def hamiltonian(Q: Array) -> Array:
        Qa = np.asarray(Q)
        tr = real_inner(stream(Qa), relative(Qa))
        return -2.0 * np.pi / N * tr

    def tendency(Q: Array) -> Array:
        Qa = np.asarray(Q)
        B = stream(Qa) / h
        return B @ Qa - Qa @ B

    def noise_weight(modes: Array) -> Array:
        assert split.linear_part is not None  # a noise acts on modes of the linear part
        return energy_weight(split.linear_part.modes(modes))

    theta = np.linspace(0.0, np.pi, ZONAL_LATITUDES)
    invariants: dict[str, Callable[[Array], Array]] = {"enstrophy": enstrophy}
    observables: dict[str, Callable[[Array], Array]] = {
        "zonal_wind": lambda Q: zonal_wind(stream(Q), theta),
    }
    if split.active:  # the linear part and the forcing change it by design
        observables.update(invariants)
        invariants.clear()
    observables.update(budget_observables(N, split, relative, stream, tendency, noise_weight))
    parameters: dict[str, Any] = {
        "N": N, "lamb": lamb_, "omega": Om, "kappa": kappa, "hbar": h, "seed": int(seed),
        "initial": kind, **extra, **split.parameters,
    }  # fmt: skip
    problem = IsospectralProblem(
        algebra=alg,
        kernel=kernel,
        hamiltonian=hamiltonian,
        invariants=invariants,
        observables=observables,
        name=f"quasi-geostrophic model on the sphere, su({N}), F = {lamb_:g}"
        + (f", kappa = {kappa:g}" if kappa else "")
        + (f", Omega = {Om:g}" if Om else ""),
        parameters=parameters,
        linear_part=split.linear_part,
        forcing=split.forcing,
    )
    return problem, Q0


#: Colatitudes of the ``zonal_wind`` diagnostic (pole to pole).
ZONAL_LATITUDES = 65


def _as_qg(built: tuple[IsospectralProblem, Array]) -> tuple[IsospectralProblem, Array]:
    """Euler's model (``F = kappa = 0``) with the QG model's zonal-wind diagnostic."""
    import dataclasses

    prob, Q0 = built
    N = Q0.shape[-1]
    F = coriolis_matrix(N, float(prob.parameters["omega"]))
    from ..sphere import solve_poisson

    theta = np.linspace(0.0, np.pi, ZONAL_LATITUDES)
    observables = dict(prob.observables)
    observables["zonal_wind"] = lambda Q: zonal_wind(solve_poisson(np.asarray(Q) - F), theta)
    params = {**prob.parameters, "lamb": 0.0, "kappa": 0.0}
    return dataclasses.replace(prob, observables=observables, parameters=params), Q0
