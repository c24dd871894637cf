r"""The isospectral minimal midpoint (IsoMP), written once against the :class:`Algebra` interface.

One step ``W_k -> W_{k+1}`` with step ``h`` (Viviani, Theorem 1):

.. math::

    W_k = (I - \tfrac h2 B(X))\, X\, (I + \tfrac h2 B(X)), \qquad
    W_{k+1} = (I + \tfrac h2 B(X))\, X\, (I - \tfrac h2 B(X)).

Expanding, ``X`` is the fixed point of

.. math::

    G(X) = W_k + \tfrac h2 [B(X), X] + \tfrac{h^2}{4} B(X) X B(X),

and :math:`W_{k+1} = W_k + h [B(X), X] = C W_k C^{-1}` with the Cayley factor
:math:`C = (I + \tfrac h2 B)(I - \tfrac h2 B)^{-1}`. The map is second order, isospectral,
symmetric (a step with ``-h`` from ``W_{k+1}`` has the same ``X``), and Lie–Poisson when
:math:`B = (\nabla H)^\dagger`.

Only ``algebra.bracket_and_triple`` and ``project`` are used, so the same code is the matrix
method on ``so(n)``, ``u(n)``, ... and the compact forms on :math:`(\mathbb{R}^3,\times)^N` and
:math:`\mathfrak{sl}(2,\mathbb{R})`. Every iterate is projected onto the stage space (``V``, or
``u(n)`` for ``su(n)``) and ``W_{k+1}`` onto ``V``, so rounding cannot push the state off ``V``.

Particles: the stage in closed form
-----------------------------------
On :math:`(\mathbb{R}^3,\times)^N` (spins, vortices on the sphere; the space's
:meth:`~isoflow.algebras.Algebra.solve_stage`) the stage equation of particle ``i`` for a
*given* field is linear: with :math:`u_i = \tfrac h2 b_i`,
:math:`w_i = x_i - u_i \times x_i + (u_i \cdot x_i)\, u_i`, whose inverse is
:math:`(I + \hat u_i)/(1 + |u_i|^2)`. The iteration is then

.. math::

    X \leftarrow g(B(X)), \qquad g_i(b) = \frac{w_i + u_i \times w_i}{1 + |u_i|^2},

with the same fixed point as :math:`G`, and the step ends with
:math:`w_i + h\, b_i \times g_i`, where ``b`` and ``g`` are the last iteration's: the Cayley
rotation of :math:`w_i` by :math:`u_i`, so every :math:`|w_i|` is kept to rounding whatever
the tolerance. The plain map contracts at about :math:`\tfrac12 \|h B\|` from the particle's
own rotation plus what comes from how ``B`` depends on ``X``; this one at the second part
alone. On spin chains and lattices, where ``B_i`` depends on the neighbours (and through a
Gilbert term, weakly, on ``x_i``), that is a fifth to a third fewer iterations a step, and
30-40% fewer with site noise, whose increments enter the particle's own rotation
(``docs/user_guide/solvers.rst`` has the measurements); on point vortices, whose field
depends on each vortex through its distances, about the same number (15.1 against 15.6 on
benchmark 7's 100 vortices).

Compensated summation
---------------------
The update :math:`W_{k+1} = W_k + hC` adds an increment far smaller than the state: rounded
to nearest, the low bits of every increment are lost, and because consecutive increments are
alike the losses add up coherently, so a Casimir drifts linearly in the number of steps. With
``compensated=True`` (the default) the step carries the rounding error ``E`` of the last
addition to the next (Kahan; the addition by Knuth's exact TwoSum, so ``W_k + d = s + e``
exactly for floating ``s, e``):

.. math::

    d = hC + E_k, \qquad s = \operatorname{fl}(W_k + d), \qquad
    W_{k+1} = \Pi_V(s), \qquad E_{k+1} = \Pi_V\big(e + (s - W_{k+1})\big).

Then only the rounding of ``C`` itself (a relative ``h\|B\| \varepsilon`` per step, of random
sign) reaches the state, and the drift grows like :math:`\varepsilon\sqrt{n}` (Brouwer's
law). ``E`` is part of the method state (:func:`state_parts`), so a checkpoint resumes bit for
bit. The compiled loops do the same in every layout.

The Cayley update
-----------------
The update ``W_k + h[B, X]`` is isospectral only at the exact fixed point: a stage solved to
a relative residual ``r`` moves the Casimirs by about ``r`` a step (with ``rtol = 1e-8``,
Euler on the sphere at ``N = 128`` drifts by 5e-9 in 200 steps). With ``update="cayley"``
the step ends instead with the Cayley factor of the accepted stage's ``B = B(X)``,

.. math::

    W_{k+1} = C W_k C^\dagger, \qquad C = (I - \tfrac h2 B)^{-1} (I + \tfrac h2 B),

a unitary (orthogonal) conjugation for every ``B`` in the skew normalizer of the dense spaces
(``so(n)``, ``u(n)``, ``su(n)``, ``sym(n)``, ``herm(n)``): the spectrum of ``W`` is kept to
rounding *whatever the tolerance*, and the step differs from IsoMP's by ``O(h r)``. With
``A = I - \tfrac h2 B`` (so :math:`A^\dagger = I + \tfrac h2 B` and ``C = 2A^{-1} - I``) and
:math:`W^\dagger = \epsilon W` (``epsilon = -1`` on skew, ``+1`` on Hermitian states), the
increment is formed without cancellation from the inverse of ``A`` and two products:

.. math::

    Y = A^{-1} W_k, \qquad Z = \big(A^{-1} Y^\dagger\big)^\dagger = A^{-1} W_k A^{-\dagger},
    \qquad W_{k+1} - W_k = 4Z - 2Y - 2\epsilon Y^\dagger,

added with the compensation above. ``A`` is well conditioned (``K = h/2 B`` is skew, so
:math:`\kappa_2(A) = \sqrt{1 + \|K\|_2^2}` at any step), so its inverse is as accurate as
solves, and faster at these sizes. The finish costs the inverse, two products and the passes:
about two fixed-point iterations (on the NumPy path also one more evaluation of ``B``, at the
accepted stage; the compiled loops keep it from the last iteration). It pays where a tight
tolerance costs more iterations than that (measured, ``docs/user_guide/solvers.rst``: Euler
on the sphere up to ``N = 128``); the stage tolerance then sets the energy error's part from
the solve, not the Casimirs.

On :math:`(\mathbb{R}^3,\times)^N` (spins, vortices on the sphere) ``B`` is ``hat(b_i)`` per
particle and the factor is the rotation :math:`C_i = I + \tfrac{2}{1 + |u_i|^2}(\hat u_i +
\hat u_i^2)`, :math:`u_i = \tfrac h2 b_i`, so
:math:`w_{k+1} - w_k = \tfrac{2}{1 + |u_i|^2}(u_i \times w_i + u_i \times (u_i \times w_i))`:
a few flops a particle, which keeps every :math:`|w_i|` (a spin's length, a vortex on its
sphere) to rounding. With the stage in closed form (above) the midpoint update is this same
rotation by the same field, written another way (the two differ in rounding only), so on these
spaces ``update="cayley"`` is the default update with a looser default tolerance (``1e-8``:
about half the iterations a step, benchmark 22).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar, Literal

import numpy as np
from numpy.typing import NDArray

from .._errors import ParameterError
from .._flags import check_flag
from ..algebras import Algebra
from ..algebras._vectors import ParticleVectors
from ..nonlinear import FixedPoint, FixedPointProblem, NonlinearSolver
from ..problems import IsospectralProblem
from ._base import Method, StepResult, check_implicit_options
from .extrapolation import interpolation_weights as extrapolation_weights
from .extrapolation import start_weights

__all__ = [
    "CAYLEY_RTOL",
    "FITTED_START",
    "FITTED_START_LARGE",
    "FITTED_START_MIN_N",
    "MAX_EXTRAPOLATION_WINDOW",
    "UPDATES",
    "IsoMP",
    "cayley_increment",
    "cayley_space",
    "check_update_space",
    "check_window",
    "compensated_update",
    "default_extrapolation_order",
    "default_start",
    "extrapolation_weights",
    "pack_state",
    "resolve_extrapolation",
    "resolve_extrapolation_order",
    "state_parts",
    "update_solver",
]

Array = NDArray[Any]


@dataclass(frozen=True)
class IsoMP(Method):
    r"""The isospectral minimal midpoint method.

    Parameters
    ----------
    solver : FixedPoint or Newton, optional
        Nonlinear solver for the stage ``X`` (default: fixed-point iteration, tolerance
        ``1e-14 ||W_k||``, or :data:`CAYLEY_RTOL` ``= 1e-8`` with ``update="cayley"``).
    initial_guess : {"extrapolate", "state"}
        Starting point of the solve. ``"state"`` is ``X = W_k`` (the paper's), an ``O(h)``
        error. ``"extrapolate"`` (default) extrapolates the stage offset ``D = G(X) - W`` of the
        last ``p + 1`` steps by the interpolating polynomial of degree ``p`` (see
        ``extrapolation_order``),

        .. math::

            X^{(0)}_k = W_k + \sum_{q=1}^{p+1} (-1)^{q+1} \binom{p+1}{q} D_{k-q},
            \qquad D_j = G(X_j) - W_j,

        an ``O(h^{p+2})`` error: with ``p = 3`` the paper's rigid body (``h = 0.1``) needs
        about 30-40% fewer fixed-point iterations than from ``W_k``; or, with an
        ``extrapolation_window`` ``K > p + 1``, by the least-squares polynomial of degree ``p``
        through the last ``K`` offsets (:mod:`isoflow.methods.extrapolation`). The first
        steps use the offsets available (none: ``W_k``). The answer is the same fixed point.
    extrapolation_order : int or None
        Polynomial degree ``p`` of the extrapolation, ``0 <= p <= 7`` (``0`` reuses the
        previous offset, ``X = W_k + D_{k-1}``). The method state then carries the last
        ``p + 1`` offsets: ``(h, D_{k-1}, D_{k-2}, ...)``, newest first. Each offset is the
        map's value at the accepted stage, ``G(X) - W``, which is closer to the fixed point
        than ``X - W`` by the map's contraction, so that high orders stay above the rounding
        of the offsets. Default ``None``: :func:`default_extrapolation_order` of the state
        space, ``p = 6`` on matrix states below ``n = 1024`` (an iteration is a few matrix
        products, worth many passes over the offsets) and ``p = 4`` on larger ones and on
        particle states (spins, vortices: an iteration is itself a few passes over memory);
        dense matrices from ``n = 512`` fit their start (``extrapolation_window``).
        Measured (one BLAS thread, ``rtol = 1e-14``, ``docs/user_guide/solvers.rst``): Euler
        on the sphere at ``h ||B||_2 = 0.3`` takes 7.52, 4.42, 3.10 iterations a step at
        ``N = 128, 256, 512`` with ``p = 6`` against 8.58, 5.68, 3.38 with ``p = 4`` (0.91,
        0.82, 0.92 of its time), the paper's rigid body so(10) (``h = 0.1``) 2.02 against
        3.01; on the spin chain the two extra offsets cost about what the iteration they save
        does. Each offset kept costs one state of memory.
    extrapolation_window : int or None
        Offsets ``K`` the start fits, ``p + 1 <= K <= 16`` (:data:`MAX_EXTRAPOLATION_WINDOW`):
        ``p + 1`` interpolates (above); more fit the degree-``p`` polynomial by least
        squares, whose error is of the same order in ``h`` with a larger constant but which
        multiplies the offsets' own errors (their rounding) far less (13.3 against 58.6 for
        degree 8 on 16 offsets against degree 6 interpolating). With a window,
        ``extrapolation_order`` may go up to ``K - 1``; a window given is always fitted.
        Default ``None``: ``p + 1`` (interpolation) when ``extrapolation_order`` is given,
        else :func:`default_start` of the space: on dense matrices from ``n = 512`` degree 8
        fitted to 16 offsets (degree 6 to 12 from ``n = 1024``), falling back step by step to
        the interpolating start of the default degree wherever that would have predicted the
        newest offset within half the tolerance (it reads fewer offsets). Euler on the sphere
        at ``h ||B||_2 = 0.3``: 2.3 iterations a step over 50 steps at ``N = 512`` against
        3.1 with the interpolating start; a linear field whose start is accepted at once keeps
        the interpolating one (``docs/user_guide/solvers.rst``).
    compensated : bool
        Carry the rounding error of the update ``W_{k+1} = W_k + hC`` to the next step
        (compensated summation, see the module docstring; default ``True``). The method state
        is then ``(h, D_{k-1}, ..., E_k, q)`` with the compensation ``E_k`` and the number
        ``q`` of offsets (:func:`state_parts`).
    update : {"midpoint", "cayley"}
        How the step ends: ``"midpoint"`` (default), :math:`W_{k+1} = W_k + h[B(X), X]`,
        isospectral to the stage's residual (on :math:`(\mathbb{R}^3,\times)^N` to rounding:
        the stage is solved per particle in closed form, see the module docstring);
        ``"cayley"``, :math:`W_{k+1} = C W_k C^\dagger` with the Cayley factor of ``B(X)``
        (the module docstring), isospectral to
        rounding whatever the solver's tolerance, for a looser tolerance and fewer
        iterations (the default solver's is then ``1e-8``). Dense matrix spaces (``so``,
        ``u``, ``su``, ``sym``, ``herm``) and particles on :math:`(\mathbb{R}^3,\times)^N`
        (spins, vortices on the sphere: a rotation per particle, every ``|w_i|`` kept). The
        method's :attr:`name` is then ``"IsoMP (Cayley update)"``, so a run resumes with the
        update it began with.

    Examples
    --------
    >>> import numpy as np, isoflow as iso
    >>> alg = iso.algebras.so(3)
    >>> prob = iso.IsospectralProblem(B=lambda W: -W, algebra=alg)
    >>> W0 = alg.random(seed=0)
    >>> W1 = iso.step(prob, iso.IsoMP(), W0, 0.1)
    """

    # ``None`` is resolved by ``__post_init__`` (it depends on ``update``): always a solver after
    solver: NonlinearSolver = None  # type: ignore[assignment]
    initial_guess: Literal["extrapolate", "state"] = "extrapolate"
    extrapolation_order: int | None = None
    compensated: bool = True
    update: Literal["midpoint", "cayley"] = "midpoint"
    extrapolation_window: int | None = None

    order: ClassVar[int] = 2
    implicit: ClassVar[bool] = True
    symmetric: ClassVar[bool] = True

    def __post_init__(self) -> None:
        object.__setattr__(self, "solver", update_solver("IsoMP", self.update, self.solver))
        K = self.extrapolation_window
        check_implicit_options(
            self.solver, self.initial_guess, self.extrapolation_order if K is None else None,
            default_order=True,
        )  # fmt: skip
        if K is not None:
            check_window(self.extrapolation_order, K)
        check_flag(self.compensated, "compensated")

    @property
    def name(self) -> str:  # type: ignore[override]
        """``"IsoMP"``, or ``"IsoMP (Cayley update)"`` with ``update="cayley"``."""
        return "IsoMP" if self.update == "midpoint" else "IsoMP (Cayley update)"

    def check_space(self, algebra: Algebra) -> None:
        """Raise if the update cannot run on ``algebra``.

        Parameters
        ----------
        algebra : Algebra
            The problem's state space.

        Raises
        ------
        ParameterError
            ``update="cayley"`` on a space without it (:func:`cayley_space`).
        """
        check_update_space("IsoMP", self.update, algebra)

    def stage_problem(
        self, problem: IsospectralProblem, W: Array, h: float,
        extra: Callable[[Array, Array | None], Array] | None = None,
    ) -> FixedPointProblem:  # fmt: skip
        """The fixed-point problem ``X = G(X)`` of one step from ``W``.

        ``extra(X, mask)`` is added to ``B(X)`` (the noise of :class:`~isoflow.StochasticIsoMP`;
        ``mask`` selects the members still iterating, ``None`` all); Newton's exact Jacobian
        is then used only if ``extra`` does not depend on ``X``, as the caller says by giving
        the problem's ``B_jvp`` or not.

        Parameters
        ----------
        problem : IsospectralProblem
            The problem to advance.
        W : ndarray, shape (*batch, *shape)
            The state ``W_k`` at the start of the step.
        h : float
            The step size.
        extra : callable, optional
            ``extra(X, mask) -> array`` of ``B``'s shape, added to ``B(X)`` (default: none).

        Returns
        -------
        FixedPointProblem
            On the stage space; its auxiliary output is the bracket ``[B(X), X]``.
        """
        alg = problem.algebra
        stage_alg = alg.stage_algebra
        half, quarter = 0.5 * h, 0.25 * h * h
        closed = alg.closed_form_stage

        def field_at(X: Array, mask: Array | None) -> Array:
            B = problem.evaluate_B(X)
            return B if extra is None else B + extra(X, mask)

        def G(X: Array, mask: Array | None) -> tuple[Array, Array]:
            Wm = W if mask is None else W[mask]
            B = field_at(X, mask)
            if closed:  # the stage for this field in closed form
                return alg.solve_stage(Wm, B, h)
            C, T = alg.bracket_and_triple(B, X)
            return stage_alg.project(Wm + half * C + quarter * T), C

        jvp = None
        if problem.B_jvp is not None and closed:

            def jvp(X: Array, dX: Array, mask: Array | None) -> Array:
                Wm = W if mask is None else W[mask]
                dB = problem.evaluate_B_jvp(X, dX)
                return alg.solve_stage_jvp(Wm, field_at(X, mask), dB, h)

        elif problem.B_jvp is not None:

            def jvp(X: Array, dX: Array, mask: Array | None) -> Array:
                B = field_at(X, mask)
                dB = problem.evaluate_B_jvp(X, dX)
                # d(BXB) = dB X B + B X dB + B dX B; the first two by polarization of the
                # quadratic map B -> B X B, with dB rescaled to the size of B for accuracy.
                nb = alg.normalizer.norm(B)
                nd = alg.normalizer.norm(dB)
                # s = ||B|| / ||dB||, and 1 where either vanishes (then dB X B + B X dB = 0
                # exactly or B = 0): never inf * 0
                ok = (nd > 0) & (nb > 0)
                s = np.where(ok, nb / np.where(ok, nd, 1.0), 1.0)
                s = s.reshape(nb.shape + (1,) * alg.core_ndim)
                _, Tp = alg.bracket_and_triple(B + s * dB, X)
                _, Tm = alg.bracket_and_triple(B - s * dB, X)
                C1, _ = alg.bracket_and_triple(dB, X)
                C2, T2 = alg.bracket_and_triple(B, dX)
                dT = (Tp - Tm) / (2.0 * s) + T2
                return stage_alg.project(half * (C1 + C2) + quarter * dT)

        scale = alg.norm(W)
        return FixedPointProblem(G=G, algebra=stage_alg, scale=scale, jvp=jvp)

    def init(self, problem: IsospectralProblem, y0: Array, h: float) -> Any:
        """No state before the first step: no stage offsets, no compensation; the space is
        checked for the update.

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
            ``None``.

        Raises
        ------
        ParameterError
            ``update="cayley"`` on a space without it (:meth:`check_space`).
        """
        self.check_space(problem.algebra)
        return None

    def order_for(self, algebra: Algebra) -> int:
        """The degree of the start's polynomial on ``algebra`` (:func:`resolve_extrapolation`)."""
        return self._start(algebra)[0]

    def window_for(self, algebra: Algebra) -> int:
        """The offsets the start fits on ``algebra`` (:func:`resolve_extrapolation`)."""
        return self._start(algebra)[1]

    def fallback_for(self, algebra: Algebra) -> int:
        """The offsets of the interpolating start the fit falls back to on ``algebra``, 0 for
        none (:func:`resolve_extrapolation`)."""
        return self._start(algebra)[2]

    def _start(self, algebra: Algebra) -> tuple[int, int, int]:
        return resolve_extrapolation(self.extrapolation_order, self.extrapolation_window, algebra)

    def history(self, h: float, state: Any, window: int) -> tuple[Array, ...]:
        """The stored stage offsets ``(D_{k-1}, D_{k-2}, ...)`` usable with step ``h``, at
        most ``window``.

        Parameters
        ----------
        h : float
            The step size of the coming step; offsets stored with another step size are not
            used.
        state : object
            The method state (:func:`pack_state`), or ``None``.
        window : int
            The offsets the start fits (:meth:`window_for`).

        Returns
        -------
        tuple of ndarray
            Empty when ``initial_guess`` is ``"state"``.
        """
        if self.initial_guess != "extrapolate":
            return ()
        offsets, _ = state_parts(state, h)
        return offsets[:window]

    def initial_stage(
        self, y: Array, offsets: tuple[Array, ...], order: int | None = None
    ) -> Array:
        """``X^(0) = W_k + sum_q a_q D_{k-q}`` with the start's weights ``a_q``.

        Parameters
        ----------
        y : ndarray, shape (*batch, *shape)
            The state ``W_k``.
        offsets : tuple of ndarray
            The stage offsets of :meth:`history` (empty: ``X^(0) = W_k``).
        order : int or None
            The degree fitted (:meth:`order_for`): interpolation through the offsets while
            there are at most ``order + 1``, least squares beyond; ``None`` interpolates
            them all (:func:`~isoflow.methods.extrapolation.start_weights`).

        Returns
        -------
        ndarray, shape (*batch, *shape)
        """
        if not offsets:
            return y
        a = start_weights(order, len(offsets))
        E = a[0] * offsets[0]
        for c, D in zip(a[1:], offsets[1:], strict=True):
            E = E + c * D
        return y + E

    def _start_or_fallback(
        self, alg: Algebra, y: Array, offsets: tuple[Array, ...], order: int, kint: int
    ) -> Array:
        """The fitted start, or per member the interpolating one on the newest ``kint``
        offsets where that would have predicted the newest offset from the ``kint`` before it
        within half the tolerance (the compiled loop's ``flat.guess_or_fit``)."""
        a = extrapolation_weights(kint)
        X_int = self.initial_stage(y, offsets[:kint])
        miss = offsets[0] - a[0] * offsets[1]
        for c, D in zip(a[1:], offsets[2 : kint + 1], strict=True):
            miss = miss - c * D
        axes = tuple(range(-len(alg.shape), 0))
        size = np.sqrt(np.sum(np.abs(miss) ** 2, axis=axes))
        scale = np.sqrt(np.sum(np.abs(y) ** 2, axis=axes))
        solver: Any = self.solver
        limit = 0.5 * (solver.atol + solver.rtol * scale)
        fallback = np.reshape(size <= limit, size.shape + (1,) * len(alg.shape))
        if np.all(fallback):
            return X_int
        return np.where(fallback, X_int, self.initial_stage(y, offsets, order))

    def step(
        self, problem: IsospectralProblem, y: Array, h: float, state: Any = None
    ) -> StepResult:
        """One IsoMP step (module docstring) with its ``update``, compensated unless
        ``compensated=False``.

        Parameters
        ----------
        problem : IsospectralProblem
            The problem to advance.
        y : ndarray, shape (*batch, *shape)
            The state at the start of the step.
        h : float
            The step size.
        state : object, optional
            The state of the previous step: stage offsets for the extrapolated initial guess and the
            compensation ``E`` (:func:`pack_state`); ``None`` before the first step.

        Returns
        -------
        StepResult
            The new state, the stage ``X``, the solve record and the state for the next step.
        """
        alg = problem.algebra
        order, window, kint = self._start(alg)
        offsets = self.history(h, state, window)
        if kint and len(offsets) > kint:
            X0 = self._start_or_fallback(alg, y, offsets, order, kint)
        else:
            X0 = self.initial_stage(y, offsets, order)
        res = self.solver.solve(self.stage_problem(problem, y, h), X0)
        kept: tuple[Array, ...] = ()
        if self.initial_guess == "extrapolate":
            kept = (res.gx - y, *offsets[: window - 1])
        if self.update == "cayley":
            self.check_space(alg)
            d = cayley_increment(alg, problem.evaluate_B(res.x), y, h)
        else:
            d = h * res.aux
        if not self.compensated:
            return StepResult.from_solve(alg.project(y + d), res, pack_state(h, kept))
        _, E = state_parts(state, h)
        y_next, E_next = compensated_update(alg, y, d, E)
        return StepResult.from_solve(y_next, res, pack_state(h, kept, E_next))


#: The updates of :class:`IsoMP` (``update=``).
UPDATES = ("midpoint", "cayley")
#: The default stage tolerance with the Cayley update, which keeps the spectrum whatever the
#: tolerance: the method's own error dominates the stage's by orders of magnitude there
#: (benchmark 22: the energy error equals the tight run's to 3e-7 of itself).
CAYLEY_RTOL = 1e-8


def update_solver(owner: str, update: Any, solver: NonlinearSolver | None) -> NonlinearSolver:
    """``solver``, or the default of the update when it is ``None`` (``FixedPoint()``, or
    ``FixedPoint(rtol=CAYLEY_RTOL)`` for ``"cayley"``), after checking ``update``.

    Parameters
    ----------
    owner : str
        The method's class name, for the message.
    update : object
        The method's ``update``, one of :data:`UPDATES`.
    solver : NonlinearSolver or None
        The solver given.

    Returns
    -------
    NonlinearSolver

    Raises
    ------
    ParameterError
        ``update`` is not one of :data:`UPDATES`.
    """
    if not isinstance(update, str) or update not in UPDATES:
        choices = ", ".join(map(repr, UPDATES))
        raise ParameterError(f"{owner}: update must be one of {choices}, got {update!r}")
    if solver is not None:
        return solver
    return FixedPoint(rtol=CAYLEY_RTOL) if update == "cayley" else FixedPoint()


def check_update_space(owner: str, update: str, algebra: Algebra) -> None:
    """Raise if ``update`` cannot run on ``algebra`` (the Cayley update on a space outside
    :func:`cayley_space`).

    Parameters
    ----------
    owner : str
        The method's class name, for the message.
    update : str
        The method's ``update``.
    algebra : Algebra
        The problem's state space.

    Raises
    ------
    ParameterError
    """
    if update == "cayley" and not cayley_space(algebra):
        raise ParameterError(
            f"{owner}(update='cayley') needs a dense matrix space (so, u, su, sym, herm) or "
            f"(R^3, x)^N, not {algebra.name}: use the midpoint update there"
        )


def cayley_space(algebra: Algebra) -> bool:
    """Whether ``update="cayley"`` runs on ``algebra``: the dense matrix spaces whose
    normalizer is skew (``so``, ``u``, ``su``, ``sym``, ``herm``), and particles on
    :math:`(\\mathbb{R}^3,\times)^N` (spins, vortices on the sphere: ``so(3)`` per
    particle)."""
    from ..algebras import Hermitian, SpecialOrthogonal, SpinVectors, Symmetric, Unitary

    dense = (SpecialOrthogonal, Unitary, Symmetric, Hermitian)
    return isinstance(algebra, dense) or type(algebra) is SpinVectors


def cayley_increment(alg: Algebra, B: Array, W: Array, h: float) -> Array:
    r"""``C W C^H - W`` with the Cayley factor ``C = (I - h/2 B)^{-1} (I + h/2 B)`` of a skew
    ``B``, formed without cancellation (the module docstring).

    On :math:`(\mathbb{R}^3,\times)^N` (particles, ``so(3)`` each) the factor is a rotation
    per particle, :math:`d_i = \tfrac{2}{1 + |u_i|^2}(u_i \times w_i + u_i \times (u_i \times
    w_i))` with :math:`u_i = \tfrac h2 b_i`, which keeps every :math:`|w_i|`.

    Parameters
    ----------
    alg : Algebra
        A space of :func:`cayley_space`: ``W`` skew (``so``, ``u``, ``su``), Hermitian
        (``sym``, ``herm``), or particles on :math:`(\mathbb{R}^3,\times)^N`.
    B : ndarray, shape (*batch, n, n) or (*batch, N, 3)
        The field at the accepted stage, skew-Hermitian (antisymmetric when real).
    W : ndarray, shape (*batch, n, n) or (*batch, N, 3)
        The state ``W_k``.
    h : float
        The step.

    Returns
    -------
    ndarray, shape of ``W``
        The increment :math:`4Z - 2Y - 2\epsilon Y^\dagger` (not yet projected onto ``V``),
        or the particles' rotations.
    """
    from ..algebras import Hermitian, SpinVectors, Symmetric

    if type(alg) is SpinVectors:
        u = (0.5 * h) * B
        c = np.cross(u, W)
        k = 2.0 / (1.0 + np.sum(u * u, axis=-1, keepdims=True))
        return np.asarray(k * (c + np.cross(u, c)))

    eps = 1.0 if isinstance(alg, (Symmetric, Hermitian)) else -1.0
    n = W.shape[-1]
    A = np.eye(n, dtype=np.result_type(B, W)) - (0.5 * h) * B
    Ai = np.linalg.inv(A)  # batched; A = I - h/2 B is well conditioned (see the compiled finish)
    Y = Ai @ W
    YH = np.conj(np.swapaxes(Y, -1, -2))
    Z = Ai @ YH
    d = 4.0 * np.conj(np.swapaxes(Z, -1, -2)) - 2.0 * Y - (2.0 * eps) * YH
    return d.reshape(W.shape)


def compensated_update(alg: Any, y: Array, d: Array, E: Array | None) -> tuple[Array, Array]:
    """``(Pi_V(y + d + E), E')``: the compensated update of the module docstring.

    The sum ``s = fl(y + (d + E))`` is split exactly into ``s + e`` (TwoSum); what the
    projection changes of ``s`` is exact too (``s`` and ``Pi_V(s)`` agree to rounding), so
    ``E' = Pi_V(e + s - Pi_V(s))`` is the part of the exact sum the new state does not hold.
    """
    if E is not None:
        d = d + E
    s = y + d
    y_next = alg.project(s)
    bb = s - y
    e = (y - (s - bb)) + (d - bb)
    return y_next, alg.project(e + (s - y_next))


def pack_state(h: float, offsets: tuple[Array, ...], E: Array | None = None) -> Any:
    """IsoMP's method state: ``(h, D_1, ..., D_q)``, or ``(h, D_1, ..., D_q, E, q)`` with the
    compensation ``E`` (``None`` for no offsets and no compensation, or a zero one: the state
    before the first step)."""
    if E is None or (not offsets and not np.any(E)):
        return (h, *offsets) if offsets else None
    return (h, *offsets, E, len(offsets))


def state_parts(state: Any, h: float) -> tuple[tuple[Array, ...], Array | None]:
    """``(offsets, E)`` of an IsoMP method state (:func:`pack_state`): the stage offsets
    ``(D_1, D_2, ...)``, newest first, if they were made with step ``h`` (else none), and the
    compensation ``E`` (``None`` if the state has none).

    A state ends with the integer ``q`` exactly when it carries a compensation; states
    written without one (``(h, D_1, ..., D_q)``, also those of earlier versions) have none.
    """
    if state is None or len(state) < 1:
        return (), None
    last = state[-1]
    if isinstance(last, (int, np.integer)) and not isinstance(last, bool):
        q = int(last)
        offsets, E = tuple(state[1 : 1 + q]), state[1 + q]
    else:
        offsets, E = tuple(state[1:]), None
    return (offsets if state[0] == h else ()), E


#: Matrix states from this size on get the quartic start by default (see
#: :func:`default_extrapolation_order`).
LARGE_MATRIX_N = 1024


def default_extrapolation_order(algebra: Algebra) -> int:
    """The degree of the extrapolated start on ``algebra`` when none is given (IsoMP's,
    IsoSyRK's).

    4 on particle states (spaces of 3-vectors such as :func:`~isoflow.algebras.so3_vectors`:
    spin chains and lattices, vortices), where one iteration streams the state a few times and
    each further offset costs about as much as it saves; 6 on matrix states (and pairs or
    stacks of them) below ``n = LARGE_MATRIX_N``, where an iteration is a few matrix products;
    4 again from there, where an interpolation of higher degree amplifies the offsets'
    errors more than it gains (Euler on the sphere at ``N = 1024``, ``h ||B||_2 = 0.3``: 2.70
    iterations a step with degree 4, 3.07 with 6; ``docs/user_guide/solvers.rst`` has the
    measurements).
    """
    if isinstance(_base_space(algebra), ParticleVectors):
        return 4
    return 4 if algebra.shape[-1] >= LARGE_MATRIX_N else 6


def _base_space(algebra: Algebra) -> Algebra:
    """The space a stack or pair of spaces is made of (``algebra`` itself otherwise)."""
    base = algebra
    while isinstance(getattr(base, "base", None), Algebra):
        base = base.base  # type: ignore[attr-defined]
    return base


def resolve_extrapolation_order(order: int | None, algebra: Algebra) -> int:
    """``order``, or :func:`default_extrapolation_order` of ``algebra`` when it is ``None``
    (the rule of every method with an interpolating start)."""
    return default_extrapolation_order(algebra) if order is None else int(order)


#: The most offsets :class:`IsoMP`'s start may fit (``extrapolation_window``).
MAX_EXTRAPOLATION_WINDOW = 16


#: Dense matrix states from this size on fit their start by least squares by default
#: (:func:`default_start`).
FITTED_START_MIN_N = 512
#: The default fit ``(p, K)`` there: degree 8 to 16 offsets below :data:`LARGE_MATRIX_N`, and
#: degree 6 to 12 from there (:data:`FITTED_START_LARGE`).
FITTED_START = (8, 16)
FITTED_START_LARGE = (6, 12)


def default_start(algebra: Algebra) -> tuple[int, int, int]:
    r"""IsoMP's start on ``algebra`` when neither degree nor window is given: ``(p, K, k)``,
    the polynomial of degree ``p`` fitted to ``K`` offsets, or, where ``k > 0``, the
    interpolating start on ``k`` offsets whenever that would have predicted the newest offset
    from the ``k`` before it within half the solve's tolerance.

    On dense matrix spaces (not stacks or pairs of them) from ``n = FITTED_START_MIN_N``:
    the fit :data:`FITTED_START` (:data:`FITTED_START_LARGE` from ``n = LARGE_MATRIX_N``)
    with the interpolating start of degree :func:`default_extrapolation_order` as fallback.
    There the offsets' rounding, which an interpolation of high degree amplifies, limits the
    start (Euler on the sphere at ``N = 512``, ``h ||B||_2 = 0.3``: the degree-6
    interpolation misses the stage by :math:`7 \cdot 10^{-14} \|W\|` and the solve takes
    three iterations a step; the fit misses by :math:`1.3 \cdot 10^{-14} \|W\|`, two), while
    where the interpolating start is accepted at once the fit's longer sum would only cost
    (benchmark 3's linear fields, 1.2 iterations a step: 19-28 % a step): the fallback keeps
    that start there (``docs/user_guide/solvers.rst``). Elsewhere ``(p, p + 1, 0)``, the
    interpolating start of degree :func:`default_extrapolation_order`.
    """
    p = default_extrapolation_order(algebra)
    n = algebra.shape[-1]
    plain_matrices = _base_space(algebra) is algebra and not isinstance(algebra, ParticleVectors)
    if plain_matrices and n >= FITTED_START_MIN_N:
        fp, K = FITTED_START if n < LARGE_MATRIX_N else FITTED_START_LARGE
        return fp, K, p + 1
    return p, p + 1, 0


def resolve_extrapolation(
    order: int | None, window: int | None, algebra: Algebra
) -> tuple[int, int, int]:
    """IsoMP's start ``(p, K, k)``: degree, offsets fitted and the fallback's offsets (0:
    none).

    Both ``None``: :func:`default_start`. ``window`` ``None``: ``(order, order + 1, 0)``
    (interpolation). ``order`` ``None`` with a window: the default degree for the space, at
    most ``window - 1``. A window given is always fitted (no fallback).
    """
    if window is None:
        if order is None:
            return default_start(algebra)
        return int(order), int(order) + 1, 0
    p = resolve_extrapolation_order(order, algebra)
    if order is None:
        return min(p, int(window) - 1), int(window), 0
    return p, int(window), 0


def check_window(order: object, window: object) -> None:
    """Check ``extrapolation_window`` (and the degree it allows).

    Raises
    ------
    ParameterError
        ``window`` not an integer in ``[1, MAX_EXTRAPOLATION_WINDOW]``, or ``order`` not
        ``None`` nor an integer in ``[0, window - 1]``.
    """
    top = MAX_EXTRAPOLATION_WINDOW
    K = window
    if isinstance(K, bool) or not isinstance(K, (int, np.integer)) or not 1 <= K <= top:
        raise ParameterError(
            f"extrapolation_window must be an integer in [1, {top}], got {window!r}"
        )
    p = order
    if p is None:
        return
    if isinstance(p, bool) or not isinstance(p, (int, np.integer)) or not 0 <= p < K:
        raise ParameterError(
            f"extrapolation_order must be an integer in [0, {int(K) - 1}] with "
            f"extrapolation_window={int(K)}, got {order!r}"
        )
