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
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

import numpy as np
from numpy.typing import NDArray

from ..nonlinear import FixedPoint, FixedPointProblem, NonlinearSolver
from ..problems import IsospectralProblem
from ._base import Method, StepResult, check_implicit_options

__all__ = ["IsoMP", "extrapolation_weights"]

Array = NDArray[Any]


@dataclass(frozen=True)
class IsoMP(Method):
    r"""The isospectral minimal midpoint method.

    Parameters
    ----------
    solver : FixedPoint or Newton
        Nonlinear solver for the stage ``X`` (default: fixed-point iteration, tolerance
        ``1e-14 ||W_k||``).
    initial_guess : {"extrapolate", "state"}
        Starting point of the solve. ``"state"`` is ``X = W_k`` (the paper's), an ``O(h)``
        error. ``"extrapolate"`` (default) extrapolates the stage offset ``D = X - W`` of the
        last ``p + 1`` steps by the interpolating polynomial of degree ``p`` (see
        ``extrapolation_order``),

        .. math::

            X^{(0)}_k = W_k + \sum_{q=1}^{p+1} (-1)^{q+1} \binom{p+1}{q} D_{k-q},
            \qquad D_j = X_j - W_j,

        an ``O(h^{p+2})`` error: with ``p = 3`` the paper's rigid body (``h = 0.1``) needs
        about 30-40% fewer fixed-point iterations than from ``W_k``. The first steps use the
        offsets available (none: ``W_k``). The answer is the same fixed point.
    extrapolation_order : int
        Polynomial degree ``p`` of the extrapolation, ``0 <= p <= 5`` (default 3; ``0`` reuses
        the previous offset, ``X = W_k + D_{k-1}``). The method state then carries the last
        ``p + 1`` offsets: ``(h, D_{k-1}, D_{k-2}, ...)``, newest first.

    Examples
    --------
    >>> import numpy as np, isoflow as iso
    >>> alg = iso.algebras.so(3)
    >>> prob = iso.IsospectralProblem(B=lambda W: -W, algebra=alg)
    >>> W0 = alg.random(seed=0)
    >>> W1 = iso.step(prob, iso.IsoMP(), W0, 0.1)
    """

    solver: NonlinearSolver = field(default_factory=FixedPoint)
    initial_guess: Literal["extrapolate", "state"] = "extrapolate"
    extrapolation_order: int = 3

    order: ClassVar[int] = 2
    implicit: ClassVar[bool] = True
    symmetric: ClassVar[bool] = True
    name: ClassVar[str] = "IsoMP"

    def __post_init__(self) -> None:
        check_implicit_options(self.solver, self.initial_guess, self.extrapolation_order)

    def stage_problem(
        self, problem: IsospectralProblem, W: Array, h: float,
        extra: Callable[[Array, Array | None], Array] | None = None,
    ) -> FixedPointProblem:  # fmt: skip
        """The fixed-point problem ``X = G(X)`` of one step from ``W``.

        ``extra(X, mask)`` is added to ``B(X)`` (the noise of :class:`~isoflow.StochasticIsoMP`;
        ``mask`` selects the members still iterating, ``None`` all); Newton's exact Jacobian
        is then used only if ``extra`` does not depend on ``X``, as the caller says by giving
        the problem's ``B_jvp`` or not.
        """
        alg = problem.algebra
        stage_alg = alg.stage_algebra
        half, quarter = 0.5 * h, 0.25 * h * h

        def field_at(X: Array, mask: Array | None) -> Array:
            B = problem.evaluate_B(X)
            return B if extra is None else B + extra(X, mask)

        def G(X: Array, mask: Array | None) -> tuple[Array, Array]:
            Wm = W if mask is None else W[mask]
            C, T = alg.bracket_and_triple(field_at(X, mask), X)
            return stage_alg.project(Wm + half * C + quarter * T), C

        jvp = None
        if problem.B_jvp is not None:

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
        return None

    def history(self, h: float, state: Any) -> tuple[Array, ...]:
        """The stored stage offsets ``(D_{k-1}, D_{k-2}, ...)`` usable with step ``h``."""
        if self.initial_guess != "extrapolate" or state is None or len(state) < 2:
            return ()
        if state[0] != h:
            return ()
        return tuple(state[1 : self.extrapolation_order + 2])

    def initial_stage(self, y: Array, offsets: tuple[Array, ...]) -> Array:
        """``X^(0) = W_k + sum_q a_q D_{k-q}`` with the extrapolation weights ``a_q``."""
        if not offsets:
            return y
        a = extrapolation_weights(len(offsets))
        E = a[0] * offsets[0]
        for c, D in zip(a[1:], offsets[1:], strict=True):
            E = E + c * D
        return y + E

    def step(
        self, problem: IsospectralProblem, y: Array, h: float, state: Any = None
    ) -> StepResult:
        alg = problem.algebra
        offsets = self.history(h, state)
        X0 = self.initial_stage(y, offsets)
        res = self.solver.solve(self.stage_problem(problem, y, h), X0)
        y_next = alg.project(y + h * res.aux)
        new_state = None
        if self.initial_guess == "extrapolate":
            new_state = (h, res.x - y, *offsets[: self.extrapolation_order])
        return StepResult.from_solve(y_next, res, new_state)


def extrapolation_weights(m: int) -> tuple[float, ...]:
    """Weights ``a_q = (-1)^(q+1) binom(m, q)``, ``q = 1..m``, of degree ``m-1`` extrapolation."""
    return tuple(float((-1) ** (q + 1) * math.comb(m, q)) for q in range(1, m + 1))
