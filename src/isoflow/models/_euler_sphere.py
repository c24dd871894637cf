r"""Zeitlin's quantized Euler equations on the (rotating) sphere, on :math:`\mathfrak{su}(N)`.

The equations and what they conserve: the Notes of :func:`isoflow.models.euler_sphere`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._errors import ParameterError
from .._seeds import generator
from ..algebras import su
from ..kernels import CompiledB
from ..problems import IsospectralProblem
from ..sphere import (
    angular_momentum,
    degree_order,
    energy,
    enstrophy,
    from_coefficients,
    hbar,
    laplacian_coefficients,
    random_coefficients,
    solve_poisson,
    vorticity_from_function,
)
from ..sphere._basis import basis_matrix
from ..sphere._operators import check_N
from ._checks import require_memory
from ._forced import budget_observables, check_double_bracket, sphere_split
from ._noise import transport_noise

__all__ = ["coriolis_matrix", "euler_sphere", "initial_vorticity", "large_scale_noise"]

Array = NDArray[Any]


#: Peak memory of building the model, in states (tracemalloc, N = 500..2000): a
#: size that does not fit in the available memory is refused before anything is allocated.
_BUILD_PEAK_STATES = 5.5


def coriolis_matrix(N: int, omega: float) -> Array:
    r"""The quantized Coriolis term :math:`F = i\,T(2\Omega\cos\theta) = 2i\Omega\hbar J_3`
    (diagonal, in ``su(N)``), :math:`J_3 = \operatorname{diag}(-s, \dots, s)`.

    Parameters
    ----------
    N : int
        Matrix size.
    omega : float
        The rotation rate :math:`\Omega` of the sphere.

    Returns
    -------
    ndarray, shape (N, N)
        Complex, diagonal.
    """
    N = check_N(N)
    m = np.arange(N) - 0.5 * (N - 1)
    return np.diag(2j * float(omega) * hbar(N) * m)


def real_parameter(v: Any, what: str, model: str = "euler_sphere") -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
        raise ParameterError(f"{model}: {what} must be a real number, got {v!r}")
    if not np.isfinite(v):
        raise ParameterError(f"{model}: {what} must be finite, got {v!r}")
    return float(v)


def initial_vorticity(
    N: int,
    initial: str | ArrayLike | Callable[[Array, Array], ArrayLike],
    seed: Any,
    *,
    lmin: int,
    lmax: int | None,
    slope: float | None,
    rms: Any,
    W0: ArrayLike | None,
    model: str,
) -> tuple[Array, str, dict[str, Any]]:
    """The initial relative vorticity in ``su(N)`` of a sphere model, its kind (``"random"``,
    ``"coefficients"``, ``"function"``, ``"matrix"``) and, for random data, the parameters of
    their spectrum (see :func:`euler_sphere` for the arguments and the errors)."""
    rms_ = real_parameter(rms, "rms", model)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ParameterError(f"{model}: seed must be an integer >= 0, got {seed!r}")
    rng = generator(int(seed), f"{model}: seed")
    lmax_ = min(10, N - 1) if lmax is None else check_N(lmax, f"{model}: lmax", minimum=1)
    if lmax_ > N - 1:
        raise ParameterError(f"{model}: lmax must be <= N - 1 = {N - 1}, got {lmax_}")
    if W0 is not None:
        if not (isinstance(initial, str) and initial == "random"):
            raise ParameterError(f"{model}: give the initial vorticity by initial or W0")
        return su(N).validate(W0, "W0"), "matrix", {}
    if isinstance(initial, str):
        if initial != "random":
            raise ParameterError(
                f"{model}: initial must be 'random', coefficients or a function, got {initial!r}"
            )
        c = random_coefficients(lmax_, lmin=lmin, slope=slope, rms=rms_, seed=rng)
        return from_coefficients(c, N), "random", {
            "lmin": int(lmin), "lmax": lmax_, "slope": slope, "rms": rms_,
        }  # fmt: skip
    if callable(initial):
        return vorticity_from_function(initial, N), "function", {}
    return from_coefficients(initial, N), "coefficients", {}


def large_scale_noise(N: int, degrees: tuple[int, ...] = (1, 2)) -> Array:
    r"""Transport noise by the stream functions :math:`Y_{lm}`, ``l`` in ``degrees``, of unit
    amplitude: the fields :math:`\hbar^{-1}\, i T_{lm}` (real harmonics), ``(m, N, N)``."""
    h = hbar(N)
    fields = [
        1j * basis_matrix(N, d, m) / h for d in degrees if d <= N - 1 for m in range(-d, d + 1)
    ]
    return np.stack(fields)


def euler_sphere(
    N: int = 128,
    omega: float = 0.0,
    initial: str | ArrayLike | Callable[[Array, Array], ArrayLike] = "random",
    seed: int = 0,
    *,
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
    double_bracket: float = 0.0,
    noise: float | ArrayLike | None = None,
    noise_seed: int | None = None,
) -> tuple[IsospectralProblem, Array]:
    r"""Zeitlin's model of the Euler equations on the sphere, and its initial state.

    Equations (Notes below): :math:`\dot Q = [B(Q), Q]` on :math:`\mathfrak{su}(N)` with
    :math:`B(Q) = \hbar^{-1}\Delta_N^{-1}Q + i\Omega J_3`, :math:`\hbar = 2/\sqrt{N^2-1}`,
    where :math:`Q = W + F` is the absolute vorticity, :math:`W = i\sum_{l,m}\omega_{lm}
    T_{lm}` the relative vorticity and :math:`F = 2i\Omega\hbar J_3` the Coriolis term. For
    ``omega = 0``, :math:`Q = W` and :math:`B(W) = \Delta_N^{-1}W/\hbar`.

    ``B`` is given as a compiled kernel
    (``CompiledB(isoflow.sphere.compiled.euler_field, ...)``, ``O(N^2)`` per evaluation:
    one tridiagonal solve per diagonal), from which the Python ``B`` is derived. It accepts
    any matrix of ``u(N)`` (the IsoMP stage has a trace, which it ignores) and returns ``B``
    in ``u(N)``.

    Time is that of the continuum equations on the unit sphere (a vorticity of size one
    turns fluid around in times of order one); the energy is
    :math:`H = -\frac{2\pi}{N}\operatorname{Re}\operatorname{Tr}(P^\dagger W) =
    \frac12\sum\omega_{lm}^2/(l(l+1))`, the enstrophy :math:`\frac{2\pi}{N}\|Q\|_F^2 =
    \frac12\int(\omega+f)^2`.

    Parameters
    ----------
    N : int
        Matrix size, ``N >= 2``; resolves degrees ``l <= N - 1``.
    omega : float
        Angular velocity :math:`\Omega` of the sphere (default 0).
    initial : "random", array_like or callable
        The initial *relative* vorticity :math:`\omega`:

        * ``"random"``: seeded random smooth field, coefficients in ``lmin <= l <= lmax``
          (:func:`isoflow.sphere.random_coefficients` with ``slope``, ``rms``);
        * real coefficients of shape ``(*batch, (L+1)^2 - 1)``, ``L <= N - 1``, in the layout
          of :func:`isoflow.sphere.lm_index` (a batch makes an ensemble);
        * a function ``f(colatitude, longitude)`` (radians), transformed with ``ducc0``.
    seed : int
        Seed of the random initial data.
    lmin, lmax : int
        Band of the random initial data (``lmax`` default ``min(10, N - 1)``).
    slope : float or None
        Expected energy spectrum :math:`E_l \propto l^{\mathrm{slope}}` of the random data;
        ``None``: white coefficients.
    rms : float
        Root-mean-square relative vorticity of the random data (default 1).
    W0 : array_like, optional
        The initial relative vorticity as matrices ``(*batch, N, N)`` in ``su(N)``, instead of
        ``initial``.
    viscosity, hyperviscosity, drag : float, (float, float), float
        Dissipation of the relative vorticity,
        :math:`\dot\omega = \dots + \nu\Delta\omega - \nu_p(-\Delta)^p\omega - \alpha\omega`,
        ``hyperviscosity=(nu_p, p)`` with ``p >= 1``: the linear part
        :class:`~isoflow.sphere.SphereDissipation` with the rates
        :math:`c_l = \nu l(l+1) + \nu_p (l(l+1))^p + \alpha`, applied exactly per degree.
        With dissipation or forcing the problem has a linear part and forcing terms, and runs
        with the split method :class:`~isoflow.Strang` (``iso.Strang()``); its diagnostics
        then include the energy and enstrophy budgets and spectra
        (:mod:`isoflow.models._forced`).
    forcing : matrix, iso.Forcing, iso.StochasticForcing or a list, optional
        Forcing of the relative vorticity: a matrix in ``su(N)`` (steady), an
        :class:`~isoflow.Forcing` (time-dependent amplitudes), white noise on a band of degrees
        (:func:`isoflow.sphere.band_forcing`).
    forcing_band, energy_rate, forcing_seed : (int, int), float, int
        The same white-noise band by its numbers (what ``isoflow run`` and TOML files give):
        degrees ``lf - dl .. lf + dl``, the mean energy injection rate (default 1), the seed of
        the noise (default 0).
    double_bracket : float
        Selective decay :math:`\alpha_{db} \ge 0`: ``B`` gains :math:`-\alpha_{db}[\Psi, Q]`
        (:func:`isoflow.sphere.compiled.euler_double_bracket_field`): the energy decreases, every
        Casimir is kept (the flow stays isospectral; IsoMP integrates it as it is). The
        problem's ``lyapunov`` is then :math:`-E` (the diagnostics report any increase of the
        energy) and the angular momentum, which it changes, is an observable.
    noise : float or array_like, optional
        Stratonovich transport noise on the large scales: a number :math:`\sigma` gives the
        eight fields of the stream functions :math:`\sigma Y_{lm}`, ``l = 1, 2``
        (:func:`large_scale_noise`); an array ``(m, N, N)`` in ``u(N)`` gives the fields.
        Integrate with :class:`~isoflow.StochasticIsoMP`.
    noise_seed : int, optional
        Seed of the noise's increments (required with ``noise``).

    Returns
    -------
    problem : IsospectralProblem
        On ``su(N)`` with the compiled kernel, ``hamiltonian`` (energy of the relative
        vorticity), ``invariants``: ``"enstrophy"`` (:math:`\frac12\int q^2`, of the state),
        ``"angular_momentum"`` (:math:`\int\omega\,x_a\,dA`, ``(3,)``; only for
        ``omega = 0``) or ``"angular_momentum_z"`` (for ``omega != 0``); with dissipation or
        forcing these are ``observables`` instead (saved and drawn, no drift), with the
        spectra, the transfer and the budgets (:mod:`isoflow.models._forced`; with the
        double bracket alone the enstrophy stays an invariant, and the momentum and the
        spectra are observables; with ``noise`` the momentum is an observable, which the
        noise changes); and
        ``parameters``: ``N, omega, hbar, seed, initial`` (``"random"``, ``"coefficients"``,
        ``"function"`` or ``"matrix"``) and, for random data, ``lmin, lmax, slope, rms``.
    Q0 : ndarray, shape (*batch, N, N)
        The initial state, :math:`W_0 + F`.

    Raises
    ------
    ParameterError
        Bad ``N``, ``omega``, ``rms``, band, ``seed`` (an integer >= 0), an unknown
        ``initial`` string, or both ``initial`` data and ``W0``; an ``N`` whose construction
        needs more memory than is available (about 88 N^2 bytes: N = 20000 needs 33 GiB).
    ShapeError
        Coefficients of a wrong length or of degree above ``N - 1``; ``W0`` of a wrong shape.
    NotInSpaceError
        ``W0`` not in ``su(N)``.

    Notes
    -----
    Continuum model: the incompressible Euler equations on the unit sphere in vorticity form,

    .. math::

        \dot\omega = \{\omega + f, \psi\}, \qquad \Delta\psi = \omega, \qquad
        u = n \times \nabla\psi, \qquad f = 2\Omega\cos\theta,

    with the Poisson bracket :math:`\{g, h\} = \frac{1}{\sin\theta}(\partial_\theta g\,
    \partial_\varphi h - \partial_\varphi g\,\partial_\theta h)` (so that :math:`\{x, y\} = z`;
    :math:`\{\omega, \psi\} = -u\cdot\nabla\omega`), colatitude :math:`\theta`, longitude
    :math:`\varphi`, and the sphere rotating with angular velocity :math:`\Omega` about the
    ``z`` axis (:math:`f` is the Coriolis parameter; :math:`\Omega > 0` is eastward, in the
    direction of increasing :math:`\varphi`).

    Zeitlin's quantization (see :mod:`isoflow.sphere` for the conventions) replaces the vorticity
    by :math:`W = i\,T(\omega) \in \mathfrak{su}(N)`, the bracket by
    :math:`\frac{1}{\hbar}[\cdot,\cdot]` with :math:`\hbar = 2/\sqrt{N^2-1}`, and the Laplacian by
    the Hoppe–Yau :math:`\Delta_N`:

    .. math::

        \dot W = \frac{1}{\hbar}[P, W + F], \qquad \Delta_N P = W, \qquad
        F = i\,T(2\Omega z) = 2i\Omega\hbar J_3 .

    The state of the problem is the **absolute vorticity** :math:`Q = W + F` (for
    :math:`\Omega = 0`, :math:`Q = W`). Since :math:`F` is a degree-one harmonic,
    :math:`\Delta_N^{-1}F = -F/2`, and the flow is isospectral in :math:`Q` with an affine ``B``:

    .. math::

        \dot Q = [B(Q), Q], \qquad
        B(Q) = \frac{1}{\hbar}\Delta_N^{-1} Q + \frac{F}{2\hbar}
             = \frac{1}{\hbar}\Delta_N^{-1} Q + i\Omega J_3,

    (:math:`\Delta_N^{-1}` on the traceless part). The Casimirs :math:`\operatorname{Tr}(Q^k)`,
    i.e. the integrals of powers of the absolute vorticity :math:`\omega + f`, are conserved (by
    IsoMP to rounding), and so is the kinetic energy of the relative vorticity :math:`W = Q - F`.
    The constant term :math:`i\Omega J_3` is the generator of the frame rotation: the solution is
    the non-rotating one seen from a frame turning with angular velocity :math:`\Omega`.

    References
    ----------
    V. Zeitlin, Finite-mode analogs of 2D ideal hydrodynamics: coadjoint orbits and local
    canonical structure, Physica D 49 (1991) 353–362; Self-consistent finite-mode
    approximations for the hydrodynamics of an incompressible fluid on nonrotating and
    rotating spheres, Phys. Rev. Lett. 93 (2004) 264501.
    J. Hoppe, S.-T. Yau, Some properties of matrix harmonics on :math:`S^2`, Comm. Math.
    Phys. 195 (1998) 67–77.
    K. Modin, M. Viviani, A Casimir preserving scheme for long-time simulation of spherical
    ideal hydrodynamics, J. Fluid Mech. 884 (2020) A22.
    P. Cifani, M. Viviani, K. Modin, An efficient geometric method for incompressible
    hydrodynamics on the sphere, J. Comput. Phys. 473 (2023) 111772.

    Examples
    --------
    >>> import isoflow as iso
    >>> prob, W0 = iso.models.euler_sphere(N=16, seed=1)
    >>> sol = iso.solve(prob, iso.IsoMP(), W0, dt=0.1, n_steps=20)
    >>> bool(sol.diagnostics.casimir_drift < 1e-12)
    True
    """
    N = check_N(N, "euler_sphere: N")
    require_memory(16.0 * N * N, _BUILD_PEAK_STATES, f"euler_sphere: N = {N}")
    Om = real_parameter(omega, "omega")
    alg = su(N)
    h = hbar(N)
    W, kind, data_params = initial_vorticity(
        N, initial, seed, lmin=lmin, lmax=lmax, slope=slope, rms=rms, W0=W0, model="euler_sphere"
    )
    seed_ = int(seed)

    F = coriolis_matrix(N, Om)
    Q0 = W + F
    coef = laplacian_coefficients(N)
    shift = 1j * Om * (np.arange(N) - 0.5 * (N - 1))  # F / (2 hbar)
    from ..sphere.compiled import euler_double_bracket_field, euler_field

    alpha = check_double_bracket(double_bracket, "euler_sphere")
    if alpha:
        kernel = CompiledB(
            euler_double_bracket_field, (coef.inv_piv, coef.mult, 1.0 / h, shift, h, alpha),
            name="euler_sphere_double_bracket_field", raises=False,
        )  # fmt: skip
    else:
        kernel = CompiledB(
            euler_field,
            (coef.inv_piv, coef.mult, 1.0 / h, shift),
            name="euler_sphere_field",
            raises=False,
        )
    split = sphere_split(
        N, viscosity=viscosity, hyperviscosity=hyperviscosity, drag=drag, forcing=forcing,
        planetary=F, model="euler_sphere", forcing_band=forcing_band, energy_rate=energy_rate,
        forcing_seed=forcing_seed,
    )  # fmt: skip

    def hamiltonian(Q: Array) -> Array:
        return energy(np.asarray(Q) - F)

    invariants: dict[str, Callable[[Array], Array]] = {"enstrophy": enstrophy}
    if Om == 0.0:
        invariants["angular_momentum"] = angular_momentum
    else:
        invariants["angular_momentum_z"] = lambda Q: angular_momentum(np.asarray(Q) - F)[..., 2]

    observables: dict[str, Callable[[Array], Array]] = {}
    if split.active:  # the linear part and the forcing change them by design
        observables.update(invariants)
        invariants.clear()
    elif alpha:  # the double bracket keeps the Casimirs (the enstrophy), not the momentum
        observables.update({k: v for k, v in invariants.items() if k != "enstrophy"})
        invariants = {"enstrophy": enstrophy}
    if split.active or alpha:

        def tendency(Q: Array) -> Array:
            Qa = np.asarray(Q)
            B = solve_poisson(Qa) / h + np.diag(shift)
            return B @ Qa - Qa @ B

        degrees = degree_order(N - 1)[0]

        def relative(Q: Array) -> Array:
            return np.asarray(Q) - F

        def noise_weight(modes: Array) -> Array:
            return 1.0 / (degrees[modes] * (degrees[modes] + 1.0))

        observables.update(
            budget_observables(
                N, split, relative, lambda Q: solve_poisson(relative(Q)), tendency, noise_weight
            )
        )

    parameters: dict[str, Any] = {"N": N, "omega": Om, "hbar": h, "seed": seed_, "initial": kind}
    parameters.update(data_params)
    parameters.update(split.parameters)
    if alpha:
        parameters["double_bracket"] = alpha
    transport = transport_noise("euler_sphere", noise, noise_seed, lambda: large_scale_noise(N))
    if transport is not None:
        parameters["noise"] = transport.parameters()
        # transport noise keeps the Casimirs (the enstrophy), not the angular momentum
        moved = {k: v for k, v in invariants.items() if k != "enstrophy"}
        observables.update(moved)
        invariants = {k: v for k, v in invariants.items() if k not in moved}
    problem = IsospectralProblem(
        algebra=alg,
        kernel=kernel,
        noise=transport,
        hamiltonian=hamiltonian,
        lyapunov=(lambda Q: -hamiltonian(Q)) if alpha and not split.active else None,
        invariants=invariants,
        observables=observables,
        name=f"Euler equations on the sphere, su({N})" + (f", Omega = {Om:g}" if Om else ""),
        parameters=parameters,
        linear_part=split.linear_part,
        forcing=split.forcing,
    )
    return problem, Q0
