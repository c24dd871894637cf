r"""Symmetric composition of a symmetric method: higher order from IsoMP and its relatives.

For a symmetric base method :math:`\varphi_h` of order ``q`` (IsoMP, the spherical or the
classical midpoint, ... :math:`\varphi_{-h} \circ \varphi_h = \mathrm{id}`) and real
coefficients :math:`\gamma_1, \dots, \gamma_m` with :math:`\gamma_{m+1-i} = \gamma_i`,

.. math::

    \Phi_h = \varphi_{\gamma_m h} \circ \dots \circ \varphi_{\gamma_2 h} \circ
    \varphi_{\gamma_1 h}

is again symmetric, and of higher order when the :math:`\gamma_i` satisfy the order
conditions. Every substep is a step of the base method, so :math:`\Phi_h` inherits what the
base preserves *exactly* (a composition of isospectral, Lie–Poisson maps is isospectral and
Lie–Poisson): with IsoMP the spectrum is kept to rounding and the map is Poisson for
:math:`B = (\nabla H)^\dagger`; with the spherical midpoint the norms :math:`|w_i|`.

Order conditions
----------------
A symmetric method of order ``q`` is, formally, the exact flow of a modified vector field with
odd powers of ``h`` only, :math:`\varphi_h = \exp(h X_1 + h^{q+1} X_{q+1} + h^{q+3} X_{q+3}
+ \dots)`. The composition is :math:`\exp(h Z(h))` with ``Z`` from the Baker–Campbell–Hausdorff
formula; it has order ``p`` iff :math:`Z = X_1 + O(h^p)`. :func:`composition_order` computes
``Z`` in the free associative algebra on :math:`X_1, X_{q+1}, \dots` truncated at degree 9
(with the ``X`` free, no cancellation particular to a problem is assumed), so it verifies the
order conditions of HLW §V.3 for any coefficient list up to order 8 (and reports 10 when all
terms through degree 9 vanish). For ``q = 2`` the first conditions are :math:`\sum\gamma_i = 1`,
:math:`\sum\gamma_i^3 = 0` (order 4), :math:`\sum \gamma_i^5 = 0` plus one condition of degree
5 (order 6).

Named schemes (half lists as printed, the middle coefficient is :math:`1 - 2\sum`; the orders
hold for a base of order 2 and were verified with :func:`composition_order`):

=================  =====  ======  =========================================================
name               order  stages  source
=================  =====  ======  =========================================================
``triple-jump-4``  4      3       Creutz–Gocksch, Suzuki, Yoshida (1990), HLW (V.3.4)
``suzuki-4``       4      5       Suzuki (1990), HLW (V.3.5)
``yoshida-6``      6      7       Yoshida (1990), solution A; HLW §V.3.2
``kahan-li-6``     6      9       Kahan–Li (1997), s9odr6a; HLW (V.3.11)
``kahan-li-8``     8      17      Kahan–Li (1997), s17odr8a; HLW (V.3.13)
=================  =====  ======  =========================================================

Warm starts
-----------
Each substep is a step of the base method of its own length :math:`\gamma_i h` with its own
method state: IsoMP's extrapolated initial guess extrapolates the stage offsets that substep
``i`` produced in the previous steps (a smooth sequence in the step index), never those of a
substep of another length or position. The composition's state is the flat tuple

.. math::

    (m,\; k_1, s_{1,1}, \dots, s_{1,k_1},\; k_2, s_{2,1}, \dots,\; \dots,\; k_m, \dots)

where ``(s_{i,1}, ..., s_{i,k_i})`` is the base method's state of position ``i`` (``k_i = -1``
when it is ``None``), so it stays ``None`` or a flat tuple of ints, floats and arrays; every
array is a base-method state entry, whose ensemble axes lead (``(*batch, ...)``).

References
----------
E. Hairer, C. Lubich, G. Wanner, *Geometric Numerical Integration*, 2nd ed., Springer (2006),
§II.4 and §V.3 (HLW).
B. Leimkuhler, S. Reich, *Simulating Hamiltonian Dynamics*, Cambridge (2004), §6.2 and
Table 6.2.
H. Yoshida, Construction of higher order symplectic integrators, Phys. Lett. A 150 (1990)
262–268.
M. Suzuki, Fractal decomposition of exponential operators with applications to many-body
theories and Monte Carlo simulations, Phys. Lett. A 146 (1990) 319–323.
W. Kahan, R.-C. Li, Composition constants for raising the orders of unconventional schemes for
ordinary differential equations, Math. Comp. 66 (1997) 1089–1099.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from .._errors import ParameterError
from ..nonlinear import STATUS_CONVERGED
from ..problems import IsospectralProblem
from ._base import Method, StepResult

__all__ = ["SCHEMES", "Composition", "composition_order"]

Array = NDArray[Any]

#: Named schemes: half list of coefficients (the middle one is ``1 - 2 * sum``) and the order
#: for a base method of order 2.
SCHEMES: dict[str, tuple[tuple[float, ...], int]] = {
    "triple-jump-4": ((1.0 / (2.0 - 2.0 ** (1.0 / 3.0)),), 4),
    "suzuki-4": ((1.0 / (4.0 - 4.0 ** (1.0 / 3.0)),) * 2, 4),
    "yoshida-6": (
        (0.78451361047755726382, 0.23557321335935813368, -1.17767998417887100695),
        6,
    ),
    "kahan-li-6": (
        (
            0.39216144400731413928,
            0.33259913678935943860,
            -0.70624617255763935981,
            0.08221359629355080023,
        ),
        6,
    ),
    "kahan-li-8": (
        (
            0.13020248308889008088,
            0.56116298177510838456,
            -0.38947496264484728641,
            0.15884190655515560090,
            -0.39590389413323757734,
            0.18453964097831570709,
            0.25837438768632204729,
            0.29501172360931029887,
        ),
        8,
    ),
}

#: Highest degree of the BCH expansion in :func:`composition_order` (orders up to 8 verified).
_MAX_DEGREE = 9
#: A term of the modified field counts as zero below this size (the coefficients are given to
#: ~1e-16; the terms that do not vanish are >= 1e-4 for the named schemes).
_ORDER_TOL = 1e-10
#: Tolerance of the symmetry and consistency checks of user coefficients.
_COEFF_TOL = 1e-12


def full_coefficients(half: Sequence[float]) -> tuple[float, ...]:
    """Symmetric coefficient list ``(g_1, ..., g_k, 1 - 2 sum g, g_k, ..., g_1)``."""
    half = tuple(float(g) for g in half)
    return (*half, 1.0 - 2.0 * math.fsum(half), *half[::-1])


@lru_cache(maxsize=16)
def _free_algebra(letters: tuple[int, ...]) -> tuple[Array, Array, Array, Array, dict]:
    """Words in the letters (each letter is its degree) up to :data:`_MAX_DEGREE`, their
    degrees, and the multiplication table ``word[i] word[j] = word[k]`` as index arrays."""
    words: list[tuple[int, ...]] = [()]
    frontier: list[tuple[int, ...]] = [()]
    while frontier:
        frontier = [(*w, a) for w in frontier for a in letters if sum(w) + a <= _MAX_DEGREE]
        words += frontier
    index = {w: i for i, w in enumerate(words)}
    ii, jj, kk = [], [], []
    for a in words:
        for b in words:
            if sum(a) + sum(b) <= _MAX_DEGREE:
                ii.append(index[a])
                jj.append(index[b])
                kk.append(index[a + b])
    degree = np.array([sum(w) for w in words])
    return np.array(ii), np.array(jj), np.array(kk), degree, index


@lru_cache(maxsize=64)
def _modified_field_terms(coefficients: tuple[float, ...], base_order: int) -> tuple[float, ...]:
    """Size of the degree-``d`` part of ``log(prod_i exp(Y(g_i)))``, ``d = 1..9``."""
    letters = (1, *range(base_order + 1, _MAX_DEGREE + 1, 2))
    ii, jj, kk, degree, index = _free_algebra(letters)
    size = len(degree)

    def mul(a: Array, b: Array) -> Array:
        return np.bincount(kk, weights=a[ii] * b[jj], minlength=size)

    one = np.zeros(size)
    one[0] = 1.0
    prod = one
    for g in coefficients:
        Y = np.zeros(size)
        for a in letters:
            Y[index[(a,)]] = g**a  # the substep of length g h: (g h)^a X_a
        term, expo = one, one
        for k in range(1, _MAX_DEGREE + 1):
            term = mul(term, Y) / k
            expo = expo + term
        prod = mul(prod, expo)
    Z = prod - one
    log = np.zeros(size)
    power = one
    for k in range(1, _MAX_DEGREE + 1):
        power = mul(power, Z)
        log += (-1) ** (k + 1) * power / k
    return tuple(
        float(np.max(np.abs(log[degree == d]))) if np.any(degree == d) else 0.0
        for d in range(1, _MAX_DEGREE + 1)
    )


def composition_order(coefficients: Sequence[float], base_order: int = 2) -> int:
    r"""Order of the composition :math:`\varphi_{\gamma_m h} \circ \dots \circ
    \varphi_{\gamma_1 h}` of a symmetric method of order ``base_order``.

    The modified vector field of the composition is expanded by the Baker–Campbell–Hausdorff
    formula in the free algebra of the base method's modified field (see the module
    docstring) through degree 9; the order is the degree of the first term beyond ``X_1``
    that does not vanish, minus one (10 when none through degree 9 does: then the order is at
    least 10). The coefficients are not required to be symmetric here.

    Parameters
    ----------
    coefficients : sequence of float
        ``(g_1, ..., g_m)``; consistency requires ``sum(g) = 1``.
    base_order : int
        Order of the symmetric base method, an even number ``>= 2``.

    Returns
    -------
    int
        The order; ``0`` if the composition is not consistent (``sum(g) != 1``).

    Examples
    --------
    >>> from isoflow.methods.composition import composition_order, full_coefficients
    >>> composition_order(full_coefficients([1 / (2 - 2 ** (1 / 3))]))
    4
    """
    if base_order < 2 or base_order % 2:
        raise ParameterError(f"base_order must be an even integer >= 2, got {base_order!r}")
    gam = tuple(float(g) for g in coefficients)
    if abs(math.fsum(gam) - 1.0) > _COEFF_TOL:
        return 0
    if base_order >= _MAX_DEGREE:
        return base_order
    terms = _modified_field_terms(gam, int(base_order))
    for d in range(2, _MAX_DEGREE + 1):
        if terms[d - 1] > _ORDER_TOL:
            return d - 1
    return _MAX_DEGREE + 1


def _pack(states: Sequence[Any]) -> tuple[Any, ...] | None:
    """Flat tuple ``(m, k_1, *s_1, ..., k_m, *s_m)`` (``k_i = -1`` for a ``None`` state)."""
    if all(s is None for s in states):
        return None
    out: list[Any] = [len(states)]
    for s in states:
        if s is None:
            out.append(-1)
        else:
            out.append(len(s))
            out.extend(s)
    return tuple(out)


def _unpack(state: Any, m: int) -> list[Any]:
    """Per-position base-method states from :func:`_pack`'s layout (all ``None`` when
    ``state`` is ``None`` or was made for a different number of substeps)."""
    fresh: list[Any] = [None] * m
    if state is None or len(state) < 1 or state[0] != m:
        return fresh
    out: list[Any] = []
    pos = 1
    for _ in range(m):
        if pos >= len(state):
            return fresh
        k = int(state[pos])
        pos += 1
        if k < 0:
            out.append(None)
        else:
            out.append(tuple(state[pos : pos + k]))
            pos += k
    return out if pos == len(state) else fresh


def _select(state: Any, mask: Array) -> Any:
    """The state of the ensemble members selected by the boolean ``mask`` over the batch axes
    (per-member arrays have the batch axes leading; scalars are shared)."""
    if state is None:
        return None
    return tuple(x[mask] if isinstance(x, np.ndarray) and x.ndim >= mask.ndim else x for x in state)


@dataclass(frozen=True)
class Composition(Method):
    r"""Symmetric composition :math:`\Phi_h = \varphi_{\gamma_m h} \circ \dots \circ
    \varphi_{\gamma_1 h}` of a symmetric method (see the module docstring).

    Parameters
    ----------
    base : Method
        A symmetric method (``base.symmetric``): :class:`~isoflow.IsoMP` on any space
        (including the compact forms on :math:`(\mathbb{R}^3,\times)^N` and the hyperbolic
        midpoint on :math:`(\mathbb{R}^3,\times_L)^N`), :class:`~isoflow.SphericalMidpoint`,
        :class:`~isoflow.ClassicalMidpoint`, :class:`~isoflow.IsoSyRK`, or a composition.
    scheme : str or sequence of float
        A named scheme, ``"triple-jump-4"``, ``"suzuki-4"`` (default), ``"yoshida-6"``,
        ``"kahan-li-6"`` or ``"kahan-li-8"``; or the full list of coefficients
        ``(g_1, ..., g_m)``, which must be symmetric (``g_i = g_{m+1-i}``) and sum to 1 (both
        to 1e-12). Give them to full double precision: the order is the one verified by
        :func:`composition_order` (terms below 1e-10 count as zero).

    Attributes
    ----------
    coefficients : tuple of float
        The full coefficient list.
    order : int
        Order of the composition (for the named schemes with a base of order 2: 4, 4, 6, 6, 8).
    implicit : bool
        That of the base method.
    name : str
        ``"<base name> o <scheme>"``, e.g. ``"IsoMP o suzuki-4"``.

    Raises
    ------
    ParameterError
        A non-symmetric base (e.g. :class:`~isoflow.RK4`), an unknown scheme name, or
        coefficients that are not symmetric, do not sum to 1, or are not finite.

    Notes
    -----
    ``step`` returns per member the number of nonlinear iterations summed over the substeps,
    the largest final residual, and the first failure code. A step in which any substep fails
    fails as a whole (the solve loop raises :class:`~isoflow.ConvergenceError` or stops);
    members whose substeps all converged still complete the whole composed step, so their
    ``y`` is correct in the failed :class:`StepResult` too.

    The solve is ``m`` times the work of one base step per step; at equal work the gain is in
    accuracy (see the order). Long runs keep the base method's invariants: IsoMP compositions
    conserve the Casimirs to rounding.

    Examples
    --------
    >>> import isoflow as iso
    >>> prob, W0 = iso.models.rigid_body(n=4)
    >>> method = iso.Composition(iso.IsoMP(), "kahan-li-8")
    >>> method.order, method.name
    (8, 'IsoMP o kahan-li-8')
    >>> sol = iso.solve(prob, method, W0, dt=0.1, t1=1.0)
    """

    base: Method
    scheme: str | tuple[float, ...] = "suzuki-4"
    coefficients: tuple[float, ...] = field(init=False, repr=False, compare=False)
    _order: int = field(init=False, repr=False, compare=False)

    symmetric: ClassVar[bool] = True

    def __post_init__(self) -> None:
        if not isinstance(self.base, Method):
            raise ParameterError(f"base must be a Method such as iso.IsoMP(), got {self.base!r}")
        if not getattr(self.base, "symmetric", False):
            raise ParameterError(
                f"{self.base.name} is not a symmetric method, so a symmetric composition does not "
                "raise its order; use a symmetric base (IsoMP, SphericalMidpoint, "
                "ClassicalMidpoint, IsoSyRK)"
            )
        base_order = int(self.base.order)
        if isinstance(self.scheme, str):
            if self.scheme not in SCHEMES:
                raise ParameterError(
                    f"unknown composition scheme {self.scheme!r} "
                    f"(choose from {', '.join(SCHEMES)}, or pass the coefficients)"
                )
            coeffs = full_coefficients(SCHEMES[self.scheme][0])
        else:
            try:
                coeffs = tuple(float(g) for g in self.scheme)
            except (TypeError, ValueError):
                raise ParameterError(
                    f"scheme must be a name or a sequence of numbers, got {self.scheme!r}"
                ) from None
            object.__setattr__(self, "scheme", coeffs)
            _check_coefficients(coeffs)
        object.__setattr__(self, "coefficients", coeffs)
        object.__setattr__(self, "_order", composition_order(coeffs, base_order))

    # ---- the Method attributes that depend on the instance ----------------------------------
    @property  # type: ignore[misc]
    def order(self) -> int:  # type: ignore[override]
        return self._order

    @property  # type: ignore[misc]
    def implicit(self) -> bool:  # type: ignore[override]
        return bool(self.base.implicit)

    @property  # type: ignore[misc]
    def name(self) -> str:  # type: ignore[override]
        if isinstance(self.scheme, str):
            label = self.scheme
        else:
            label = f"custom-{self._order} ({len(self.coefficients)} stages)"
        return f"{self.base.name} o {label}"

    @property
    def stages(self) -> int:
        """Number of substeps ``m``."""
        return len(self.coefficients)

    # ---- stepping -----------------------------------------------------------------------------
    def init(self, problem: IsospectralProblem, y0: Array, h: float) -> Any:
        """The base's initial state for each substep ``gamma_i h``, packed in one tuple.

        Parameters
        ----------
        problem : IsospectralProblem
            The problem to advance.
        y0 : ndarray, shape (*batch, *shape)
            The initial state, in the problem's space.
        h : float
            The step size.

        Returns
        -------
        object
            The base's states of the substeps (``None`` when the base keeps none).
        """
        return _pack([self.base.init(problem, y0, g * h) for g in self.coefficients])

    def step(
        self, problem: IsospectralProblem, y: Array, h: float, state: Any = None
    ) -> StepResult:
        """The substeps ``gamma_1 h, ..., gamma_m h`` of the base, one after the other.

        Parameters
        ----------
        problem : IsospectralProblem
            The problem to advance.
        y : ndarray, shape (*batch, *shape)
            The state at the start of the step.
        h : float
            The step size.
        state : object, optional
            The packed states of the substeps from :meth:`init` or the previous step (``None``: each
            substep starts without history).

        Returns
        -------
        StepResult
            The new state; for an implicit base the iterations summed over the substeps, the
            largest residual, and a failed member's first failure code (it keeps the output
            of the substep that failed).
        """
        alg = problem.algebra
        m = len(self.coefficients)
        states = _unpack(state, m)
        batch = alg.batch_shape(y)
        implicit = self.base.implicit
        iterations = np.zeros(batch, dtype=np.int64)
        residual = np.zeros(batch)
        status = np.full(batch, STATUS_CONVERGED, dtype=np.int64)
        new_states: list[Any] = []
        out = y
        # ``live``: members still stepping (``None``: all of them, arrays in full shape)
        live: Array | None = None
        cur = y
        for i, g in enumerate(self.coefficients):
            sub_state = states[i] if live is None else _select(states[i], live)
            res = self.base.step(problem, cur, g * h, sub_state)
            sel = (...,) if live is None else live
            if implicit and res.status is not None:
                iterations[sel] += np.asarray(res.iterations)
                residual[sel] = np.maximum(residual[sel], np.asarray(res.residual))
                failed = np.asarray(res.status) != STATUS_CONVERGED
            else:
                failed = np.zeros(np.shape(residual[sel]), dtype=bool)
            new_states.append(res.state)
            if not failed.any():
                cur = res.y
                continue
            # the failed members keep this substep's output and first failure code; the others
            # finish the composed step (a single system stops here)
            if batch == ():
                status = np.asarray(res.status, dtype=np.int64)
                out = res.y
                break
            res_y, res_status = np.asarray(res.y), np.asarray(res.status)
            if live is None:
                out = np.array(res_y, copy=True)
                live = np.ones(batch, dtype=bool)
                failed = failed.reshape(-1)
                res_y = res_y.reshape(-1, *alg.shape)
                res_status = res_status.reshape(-1)
            else:
                out[live] = res_y
            codes = status[live]
            codes[failed] = res_status[failed]
            status[live] = codes
            cur = res_y[~failed]
            live = live.copy()
            live[live] = ~failed
            if not live.any():
                break
        else:
            if live is None:
                out = cur
            else:
                out[live] = cur
        failed_step = bool(np.any(status != STATUS_CONVERGED))
        return StepResult(
            y=out,
            stage=None,
            iterations=iterations if implicit else None,
            residual=residual if implicit else None,
            status=status if implicit else None,
            state=state if failed_step else _pack(new_states),
        )


def _check_coefficients(coeffs: tuple[float, ...]) -> None:
    """User coefficients: finite, symmetric and consistent (each to 1e-12)."""
    if len(coeffs) == 0:
        raise ParameterError("a composition needs at least one coefficient")
    if not all(math.isfinite(g) for g in coeffs):
        raise ParameterError(f"composition coefficients must be finite, got {coeffs}")
    asym = max(abs(a - b) for a, b in zip(coeffs, coeffs[::-1], strict=True))
    if asym > _COEFF_TOL * max(1.0, max(abs(g) for g in coeffs)):
        raise ParameterError(
            f"composition coefficients must be symmetric (g_i = g_(m+1-i)); they differ by up "
            f"to {asym:.3e}"
        )
    total = math.fsum(coeffs)
    if abs(total - 1.0) > _COEFF_TOL:
        raise ParameterError(f"composition coefficients must sum to 1, they sum to {total!r}")
