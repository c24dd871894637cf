r"""Dissipation and forcing beside an isospectral flow, and the Strang splitting that integrates
them.

A problem (:class:`~isoflow.IsospectralProblem`) may carry, besides its ``B``, a *linear part*
``L`` and *forcings*:

.. math::

    dW = \big([B(W), W] + L W + F(t)\big)\,dt + \sum_j \sigma_j e_j\, d\beta_j(t).

``L`` is diagonal in an orthonormal basis :math:`(e_j)` of the space (orthonormal in the
space's pairing :meth:`Algebra.inner <isoflow.algebras.Algebra.inner>`): :math:`L e_j = -c_j
e_j` with rates :math:`c_j \ge 0` (viscosity, hyperviscosity, linear drag, ...), and acts as
zero on what the basis does not span. Two are built in: :class:`ModalLinearPart` (any basis you
give) and the sphere's per-degree dissipation (:class:`isoflow.sphere.SphereDissipation`,
diagonal in the quantized spherical harmonics, applied per diagonal of the matrix).
A :class:`Forcing` is deterministic, :math:`F(t) = \sum_j a_j(t) F_j`; a
:class:`StochasticForcing` is additive white noise on modes :math:`e_j` of ``L``.

The split step
--------------
:class:`Strang` composes a method :math:`\Psi_h` for the isospectral part (IsoMP by default)
with the flow :math:`S_\tau` of the rest (Strang splitting, second order and symmetric):

.. math::

    \Phi_h = S_{h/2} \circ \Psi_h \circ S_{h/2},

where :math:`S_\tau` is the exact flow of :math:`\dot W = LW + F`, per mode
:math:`w_j \mapsto e^{-c_j\tau} w_j + \varphi_j(\tau) f_j`, :math:`\varphi_j(\tau) = \int_0^\tau
e^{-c_j s}\,ds = (1 - e^{-c_j\tau})/c_j` (:math:`\tau` for :math:`c_j = 0`). A forcing with
time-dependent amplitudes takes them at the midpoint of each half step (second order, and
symmetric); noise enters each half step by its exact Ornstein–Uhlenbeck law, the Gaussian
:math:`\sigma_j \sqrt{(1 - e^{-2c_j\tau})/(2c_j)}\,\xi_j` (:math:`\sigma_j\sqrt\tau\,\xi_j` for
:math:`c_j = 0`), so that with the bracket off the stationary variance
:math:`\sigma_j^2/(2c_j)` is exact for every step. The isospectral part keeps its Casimirs
exactly; what changes them is the linear part and the forcing alone. With no linear part and no
forcing the split step is the method's own step, bit for bit.

The derivations (signs, the energy and enstrophy budgets, the injection rate of the noise) are
in ``docs/theory/forced.rst``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._errors import NonFiniteError, ParameterError, ShapeError

if TYPE_CHECKING:
    from .algebras import Algebra
    from .problems import IsospectralProblem

__all__ = [
    "FORCING_STREAM",
    "Forcing",
    "HalfStep",
    "LinearPart",
    "ModalLinearPart",
    "StochasticForcing",
    "data_widths",
    "decay_factors",
    "half_step",
    "has_split_part",
    "ou_scales",
    "phi_factors",
    "split_terms",
]

Array = NDArray[Any]

#: The Philox stream of a stochastic forcing's noise (``isoflow.noise``).
FORCING_STREAM = 1


def decay_factors(rates: ArrayLike, tau: float) -> Array:
    r""":math:`e^{-c\tau}` per rate ``c``.

    Parameters
    ----------
    rates : array_like
        The rates :math:`c \ge 0` (any shape).
    tau : float
        The time span.

    Returns
    -------
    ndarray
        Of the shape of ``rates``.
    """
    return np.exp(-np.asarray(rates, dtype=float) * tau)


def phi_factors(rates: ArrayLike, tau: float) -> Array:
    r""":math:`\int_0^\tau e^{-cs}\,ds = (1 - e^{-c\tau})/c` per rate (``tau`` where ``c = 0``),
    computed as ``-expm1(-c tau)/c`` (no cancellation for small ``c tau``).

    Parameters
    ----------
    rates : array_like
        The rates :math:`c \ge 0` (any shape).
    tau : float
        The time span.

    Returns
    -------
    ndarray
        Of the shape of ``rates``.
    """
    c = np.asarray(rates, dtype=float)
    safe = np.where(c > 0, c, 1.0)
    return np.where(c > 0, -np.expm1(-c * tau) / safe, tau)


def ou_scales(rates: ArrayLike, tau: float) -> Array:
    r"""The standard deviation per unit :math:`\sigma` of the Ornstein–Uhlenbeck increment over
    ``tau``: :math:`\sqrt{(1 - e^{-2c\tau})/(2c)}` (:math:`\sqrt\tau` where ``c = 0``).

    Parameters
    ----------
    rates : array_like
        The rates :math:`c \ge 0` (any shape).
    tau : float
        The time span.

    Returns
    -------
    ndarray
        Of the shape of ``rates``.
    """
    c = np.asarray(rates, dtype=float)
    safe = np.where(c > 0, c, 1.0)
    return np.sqrt(np.where(c > 0, -np.expm1(-2.0 * c * tau) / (2.0 * safe), tau))


def _check_rates(rates: ArrayLike, what: str) -> Array:
    c = np.asarray(rates, dtype=float)
    if c.ndim != 1:
        raise ShapeError(f"{what}: rates must be a 1-d array, one per mode, got shape {c.shape}")
    if not np.all(np.isfinite(c)):
        raise NonFiniteError(f"{what}: rates must be finite (found NaN or Inf)")
    if np.any(c < 0):
        raise ParameterError(
            f"{what}: rates must be >= 0 (a negative rate makes the mode grow "
            f"exponentially), got {float(c.min())!r}"
        )
    return c


class LinearPart(ABC):
    r"""A linear part :math:`L = -\sum_j c_j\, e_j \langle e_j, \cdot\rangle` of a problem.

    Subclasses give the rates, the exact flow, its integral against a forcing, the modes
    :math:`e_j` (for stochastic forcing) and the compiled form (see
    :mod:`isoflow._compiled.stages.split`).
    """

    name: str = "linear part"

    @abstractmethod
    def check(self, algebra: Algebra) -> None:
        """Raise a typed one-line error if the part does not act on ``algebra``."""

    @property
    @abstractmethod
    def rates(self) -> Array:
        """The rates :math:`c_j \\ge 0` of the modes."""

    @abstractmethod
    def flow(self, W: Array, tau: float) -> Array:
        r""":math:`e^{\tau L} W` for ``W`` of shape ``(*batch, *core)``."""

    @abstractmethod
    def integral(self, F: Array, tau: float) -> Array:
        r""":math:`\int_0^\tau e^{sL} F\,ds` (the response of the flow to a constant ``F``)."""

    @abstractmethod
    def modes(self, index: ArrayLike) -> Array:
        """The basis elements :math:`e_j` of the modes ``index``, ``(r, *core)``."""

    def mode_patterns(self, index: ArrayLike) -> Any:
        """The modes ``index`` as the rows of a sparse ``(r, prod(core))`` matrix
        (``scipy.sparse.csr_array``, sorted indices, no stored zeros): what a half step adds
        of a stochastic forcing. By default :meth:`modes` sparsified a few at a time; a part
        whose modes are sparse builds them directly (the sphere's: two diagonals each)."""
        from scipy import sparse

        idx = np.asarray(index, dtype=np.int64).reshape(-1)
        rows = [
            sparse.csr_array(self.modes(idx[k : k + 64]).reshape(len(idx[k : k + 64]), -1))
            for k in range(0, idx.size, 64)
        ]
        out = sparse.csr_array(sparse.vstack(rows, format="csr"))
        out.eliminate_zeros()
        out.sort_indices()
        return out

    @abstractmethod
    def compiled(self, taus: Sequence[float], algebra: Algebra) -> Any:
        """The record the compiled split stage applies for the half steps ``taus``.

        Parameters
        ----------
        taus : sequence of float
            The lengths of the half steps of one step.
        algebra : Algebra
            The problem's space (its shape and dtype).

        Returns
        -------
        object
            The record of :mod:`isoflow._compiled.stages.split` for these half steps.
        """

    def describe(self) -> dict[str, Any]:
        """What identifies the part (recorded with results)."""
        return {"name": self.name}


class ModalLinearPart(LinearPart):
    r"""``L`` diagonal in a basis you give: :math:`L e_j = -c_j e_j`, zero on the rest.

    Parameters
    ----------
    basis : array_like, shape (r, *core)
        Elements :math:`e_j` of the space, orthonormal in its pairing (checked when the problem
        is built, to ``1e-10``).
    rates : array_like, shape (r,)
        :math:`c_j \ge 0`.

    Notes
    -----
    Its flow costs ``2 r`` passes over the state: fine for small spaces; the sphere has its own
    per-diagonal part (:class:`isoflow.sphere.SphereDissipation`).
    """

    name = "modal linear part"

    def __init__(self, basis: ArrayLike, rates: ArrayLike) -> None:
        E = np.asarray(basis)
        if E.dtype.kind not in "iufc":
            raise ParameterError(f"ModalLinearPart: basis must be numeric, got dtype {E.dtype}")
        if not np.all(np.isfinite(E)):
            raise NonFiniteError("ModalLinearPart: basis must be finite (found NaN or Inf)")
        self.basis = E
        self._rates = _check_rates(rates, "ModalLinearPart")
        if E.shape[:1] != self._rates.shape:
            raise ShapeError(
                f"ModalLinearPart: {self._rates.size} rates for {E.shape[0] if E.ndim else 0} "
                "basis elements (basis of shape (r, *core), rates of shape (r,))"
            )

    @property
    def rates(self) -> Array:
        return self._rates

    def check(self, algebra: Algebra) -> None:
        E = algebra.validate(self.basis, "ModalLinearPart basis")
        if E.shape[: E.ndim - algebra.core_ndim] != self._rates.shape:
            raise ShapeError(
                f"ModalLinearPart: the basis must have shape (r, *{algebra.shape}) for "
                f"{algebra.name}, got {self.basis.shape}"
            )
        gram = algebra.inner(E[:, None], E[None, :])
        gap = float(np.max(np.abs(gram - np.eye(len(E))))) if len(E) else 0.0
        if gap > 1e-10:
            raise ParameterError(
                f"ModalLinearPart: the basis is not orthonormal in the pairing of "
                f"{algebra.name} (Gram matrix off the identity by {gap:.2e}); orthonormalize it "
                "(e.g. by a QR factorization of its coordinates)"
            )
        self.basis = E
        self._algebra = algebra

    def _coefficients(self, W: Array) -> Array:
        alg = self._algebra
        Wb = np.expand_dims(W, -alg.core_ndim - 1)  # (*batch, 1, *core)
        return np.asarray(alg.inner(self.basis, Wb))  # (*batch, r)

    def _combine(self, W: Array, coef: Array) -> Array:
        E = self.basis
        k = self._algebra.core_ndim
        return W + np.tensordot(coef, E, axes=(-1, 0)) if k else W + coef @ E

    def flow(self, W: Array, tau: float) -> Array:
        coef = self._coefficients(W) * (decay_factors(self._rates, tau) - 1.0)
        return self._combine(W, coef)

    def integral(self, F: Array, tau: float) -> Array:
        coef = self._coefficients(F) * (phi_factors(self._rates, tau) - tau)
        return self._combine(tau * F, coef)

    def modes(self, index: ArrayLike) -> Array:
        return np.asarray(self.basis[np.asarray(index, dtype=np.int64)])

    def compiled(self, taus: Sequence[float], algebra: Algebra) -> Any:
        r"""The modal flow of the half steps ``taus``: the basis flattened and the factors
        :math:`e^{-c_j\tau} - 1`.

        Parameters
        ----------
        taus : sequence of float
            The lengths of the half steps of one step.
        algebra : Algebra
            The problem's space (the basis is flattened to its size, in its dtype).

        Returns
        -------
        object
            A ``ModalFlow`` record of :mod:`isoflow._compiled.stages.split`.
        """
        from ._compiled.stages.split import ModalFlow

        S = int(np.prod(algebra.shape))
        E = np.ascontiguousarray(self.basis.reshape(len(self.basis), S), dtype=algebra.dtype)
        decay = np.ascontiguousarray([decay_factors(self._rates, t) - 1.0 for t in taus])
        return ModalFlow(E, decay.reshape(len(taus), len(self._rates)))

    def describe(self) -> dict[str, Any]:
        return {"name": self.name, "modes": int(self._rates.size)}


@dataclass(frozen=True)
class Forcing:
    r"""A deterministic forcing :math:`F(t) = \sum_j a_j(t) F_j`.

    Parameters
    ----------
    pattern : array_like, shape (*core) or (r, *core)
        The patterns :math:`F_j`, elements of the problem's space.
    amplitude : callable or None
        ``a(t) -> (r,)`` (a float for one pattern); ``None``: constant ``1`` (a steady
        forcing). A time-dependent amplitude is taken at the midpoint of each half step.
    """

    pattern: ArrayLike
    amplitude: Callable[[float], ArrayLike] | None = None

    def patterns(self, algebra: Algebra) -> Array:
        """The patterns ``(r, *core)``, checked to lie in ``algebra``'s space.

        Raises
        ------
        NotInSpaceError, ShapeError, DtypeError, NonFiniteError
            A pattern outside the space, of another shape, or not finite.
        """
        P = np.asarray(self.pattern)
        if P.ndim == algebra.core_ndim:
            P = P[None]
        if P.ndim != algebra.core_ndim + 1:
            raise ShapeError(
                f"forcing: the pattern must have shape {algebra.shape} or (r, *{algebra.shape}) "
                f"for {algebra.name}, got {np.shape(self.pattern)}"
            )
        return algebra.validate(P, "forcing pattern")

    @property
    def time_dependent(self) -> bool:
        return self.amplitude is not None

    def amplitudes(self, t: float, r: int) -> Array:
        """``a(t)`` as a finite ``(r,)`` array (one line of error otherwise)."""
        assert self.amplitude is not None
        a = np.asarray(self.amplitude(float(t)), dtype=float).reshape(-1)
        if a.shape != (r,):
            raise ShapeError(f"forcing: amplitude(t) must give {r} numbers, got shape {a.shape}")
        if not np.all(np.isfinite(a)):
            raise NonFiniteError(f"forcing: amplitude({t!r}) is not finite")
        return a


@dataclass(frozen=True)
class StochasticForcing:
    r"""Additive white noise :math:`\sum_j \sigma_j e_j\,d\beta_j` on modes of the linear part.

    Parameters
    ----------
    modes : array_like of int, shape (r,)
        Indices of the modes :math:`e_j` of the problem's linear part (for the sphere the flat
        coefficient index :func:`isoflow.sphere.lm_index`; see
        :func:`isoflow.sphere.band_forcing`).
    sigma : array_like, shape (r,) or scalar
        Amplitudes :math:`\sigma_j \ge 0`.
    seed : int
        The noise seed: member ``m`` of a run draws with the key ``(seed, m)`` at every step,
        the same in a resumed or split run (:mod:`isoflow.noise`).

    Notes
    -----
    The mean rate of energy injected into mode ``j`` in a pairing where the energy is
    :math:`\frac12\sum_j w_j^2/\lambda_j` is :math:`\frac12\sigma_j^2/\lambda_j` (Itô).
    """

    modes: ArrayLike
    sigma: ArrayLike
    seed: int = 0

    def checked(self, linear: LinearPart | None) -> tuple[Array, Array]:
        """``(modes, sigma)`` as arrays, checked against ``linear``.

        Raises
        ------
        ParameterError
            No linear part to take the modes from, modes out of range, a negative seed.
        NonFiniteError
            A non-finite amplitude.
        """
        if linear is None:
            raise ParameterError(
                "stochastic forcing acts on modes of the problem's linear part: give the "
                "problem a linear_part (rates may be zero)"
            )
        modes = np.asarray(self.modes, dtype=np.int64).reshape(-1)
        sigma = np.broadcast_to(np.asarray(self.sigma, dtype=float), modes.shape).copy()
        if not np.all(np.isfinite(sigma)):
            raise NonFiniteError("stochastic forcing: sigma must be finite (found NaN or Inf)")
        if np.any(sigma < 0):
            raise ParameterError("stochastic forcing: sigma must be >= 0")
        n = linear.rates.size
        if modes.size == 0 or np.any(modes < 0) or np.any(modes >= n):
            got = f"{modes.min()}..{modes.max()}" if modes.size else "none"
            raise ParameterError(
                f"stochastic forcing: modes must be indices 0..{n - 1} of the linear part's "
                f"modes, got {got}"
            )
        s = self.seed
        if isinstance(s, bool) or not isinstance(s, (int, np.integer)) or s < 0:
            raise ParameterError(f"stochastic forcing: seed must be an integer >= 0, got {s!r}")
        return modes, sigma


@dataclass(frozen=True)
class HalfStep:
    """What a half step of length ``tau`` adds: the steady part (a matrix), the
    time-dependent responses ``G`` (one per amplitude) and the noise patterns scaled by
    their Ornstein–Uhlenbeck deviations."""

    steady: Array | None
    responses: Array | None  # (R_d, *core)
    noise: Any  # (R_s, prod(core)) scipy.sparse.csr_array, or None


Deterministic = list[tuple[Forcing, Array]]
Stochastic = list[tuple[StochasticForcing, Array, Array]]


def split_terms(problem: IsospectralProblem) -> tuple[Deterministic, Stochastic]:
    """The problem's deterministic forcings with their checked patterns, and its stochastic
    forcings with their modes and amplitudes."""
    alg = problem.algebra
    terms: tuple[Forcing | StochasticForcing, ...] = problem.forcing  # type: ignore[assignment]
    det = [(f, f.patterns(alg)) for f in terms if isinstance(f, Forcing)]
    sto = [(f, *f.checked(problem.linear_part)) for f in terms if isinstance(f, StochasticForcing)]
    return det, sto


def half_step(problem: IsospectralProblem, tau: float) -> HalfStep:
    """The forcing terms of a half step of length ``tau`` (precomputed once per step size).

    Parameters
    ----------
    problem : IsospectralProblem
        A problem with a forcing (and possibly a linear part; a stochastic forcing needs one).
    tau : float
        The length of the half step.

    Returns
    -------
    HalfStep
        The steady forcing's response, the responses of the time-dependent patterns, and the
        noise modes scaled by their Ornstein–Uhlenbeck standard deviations (sparse).
    """
    lin = problem.linear_part
    det, sto = split_terms(problem)

    def response(F: Array) -> Array:
        return lin.integral(F, tau) if lin is not None else tau * F

    steady = None
    responses = []
    for f, P in det:
        G = response(P)
        if f.time_dependent:
            responses.append(G)
        else:
            s = G.sum(axis=0)
            steady = s if steady is None else steady + s
    noise = []
    from scipy import sparse

    for _, modes, sigma in sto:
        assert lin is not None
        scale = sigma * ou_scales(lin.rates[modes], tau)
        E = lin.mode_patterns(modes)  # sparse: a band of harmonics is two diagonals each
        noise.append(sparse.csr_array(sparse.diags_array(scale) @ E))  # row j times its scale
    if noise:
        stacked = sparse.csr_array(sparse.vstack(noise, format="csr"))
        stacked.sort_indices()
    return HalfStep(
        steady,
        np.concatenate(responses) if responses else None,
        stacked if noise else None,
    )


def data_widths(
    problem: IsospectralProblem, terms: tuple[Deterministic, Stochastic] | None = None
) -> tuple[int, int]:
    """``(R_d, R_s)``: the time-dependent amplitudes and the noise modes of a half step (the
    step data of a split step holds ``2 (R_d + R_s)`` numbers per member); ``terms``: the
    problem's :func:`split_terms` if at hand (they check every pattern against the space)."""
    det, sto = split_terms(problem) if terms is None else terms
    rd = sum(len(P) for f, P in det if f.time_dependent)
    rs = sum(len(m) for _, m, _ in sto)
    return rd, rs


def has_split_part(problem: IsospectralProblem) -> bool:
    """Whether the problem has a linear part or a forcing (a split method must integrate it)."""
    return problem.linear_part is not None or bool(problem.forcing)
