r"""The classical implicit midpoint rule on ``V``, for comparison.

:math:`W_{k+1} = W_k + h\,[B(M), M]`, :math:`M = (W_k + W_{k+1})/2`, i.e. ``M`` is the fixed
point of :math:`G(M) = W_k + \tfrac h2 [B(M), M]`. Second order and symmetric; it keeps ``W``
in ``V`` but is neither isospectral nor Lie–Poisson in general (it is Lie–Poisson on
:math:`(\mathbb{R}^3, \times)` only for Hamiltonians constant on rays).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

from numpy.typing import NDArray

from ..nonlinear import FixedPoint, FixedPointProblem, NonlinearSolver
from ..problems import IsospectralProblem
from ._base import Method, StepResult

__all__ = ["ClassicalMidpoint"]

Array = NDArray[Any]


@dataclass(frozen=True)
class ClassicalMidpoint(Method):
    """Implicit midpoint rule applied to ``W' = [B(W), W]``.

    Parameters
    ----------
    solver : FixedPoint or Newton
        Nonlinear solver for the midpoint ``M``.
    """

    solver: NonlinearSolver = field(default_factory=FixedPoint)

    order: ClassVar[int] = 2
    implicit: ClassVar[bool] = True
    symmetric: ClassVar[bool] = True
    name: ClassVar[str] = "classical midpoint"

    def stage_problem(self, problem: IsospectralProblem, W: Array, h: float) -> FixedPointProblem:
        r"""The fixed-point problem :math:`M = W + \tfrac h2 [B(M), M]` of one step from ``W``.

        ``G`` also returns the bracket :math:`[B(M), M]` (projected), which makes the update
        :math:`W + h [B(M), M]`.

        Parameters
        ----------
        problem : IsospectralProblem
            The problem to advance.
        W : ndarray, shape (*batch, *shape)
            The state at the start of the step.
        h : float
            The step size.

        Returns
        -------
        FixedPointProblem
            With Newton's Jacobian-vector product when the problem has ``B_jvp``.
        """
        alg = problem.algebra
        half = 0.5 * h

        def G(M: Array, mask: Array | None) -> tuple[Array, Array]:
            Wm = W if mask is None else W[mask]
            C = alg.project(alg.bracket(problem.evaluate_B(M), M))
            return Wm + half * C, C

        jvp = None
        if problem.B_jvp is not None:

            def jvp(M: Array, dM: Array, mask: Array | None) -> Array:
                B = problem.evaluate_B(M)
                dB = problem.evaluate_B_jvp(M, dM)
                return alg.project(half * (alg.bracket(dB, M) + alg.bracket(B, dM)))

        return FixedPointProblem(G=G, algebra=alg, scale=alg.norm(W), jvp=jvp)

    def step(
        self, problem: IsospectralProblem, y: Array, h: float, state: Any = None
    ) -> StepResult:
        """One step: the midpoint solved from ``y``, then ``y + h [B(M), M]`` projected.

        Parameters
        ----------
        problem : IsospectralProblem
            The problem to advance.
        y : ndarray, shape (*batch, *shape)
            The state at the start of the step.
        h : float
            The step size.
        state : object, optional
            Ignored (the method keeps no state; the solve starts from ``y``).

        Returns
        -------
        StepResult
            The new state, the midpoint and the solve record.
        """
        res = self.solver.solve(self.stage_problem(problem, y, h), y)
        y_next = problem.algebra.project(y + h * res.aux)
        return StepResult.from_solve(y_next, res)
