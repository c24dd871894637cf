r"""Explicit Runge–Kutta baselines (not structure preserving), for comparison."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

from numpy.typing import NDArray

from ..problems import IsospectralProblem
from ._base import Method, StepResult

__all__ = ["RK4"]

Array = NDArray[Any]


@dataclass(frozen=True)
class RK4(Method):
    r"""The classical fourth-order Runge–Kutta method on :math:`\dot W = [B(W), W]`.

    Stays in ``V`` (every stage is a linear combination of brackets) but is neither isospectral
    nor Lie–Poisson: a baseline that shows what structure preservation buys.
    """

    order: ClassVar[int] = 4
    implicit: ClassVar[bool] = False
    symmetric: ClassVar[bool] = False
    name: ClassVar[str] = "RK4"

    def step(
        self, problem: IsospectralProblem, y: Array, h: float, state: Any = None
    ) -> StepResult:
        """One classical Runge–Kutta step on the vector field ``[B(W), W]``, projected.

        Parameters
        ----------
        problem : IsospectralProblem
            The problem to advance.
        y : ndarray, shape (*batch, *shape)
            The state at the start of the step.
        h : float
            The step size.
        state : object, optional
            Ignored (no state).

        Returns
        -------
        StepResult
            The new state.
        """
        f = problem.vector_field
        k1 = f(y)
        k2 = f(y + 0.5 * h * k1)
        k3 = f(y + 0.5 * h * k2)
        k4 = f(y + h * k3)
        return StepResult(y=problem.algebra.project(y + (h / 6.0) * (k1 + 2 * k2 + 2 * k3 + k4)))
