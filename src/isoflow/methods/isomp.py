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

from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

import numpy as np
from numpy.typing import NDArray

from ..nonlinear import FixedPoint, FixedPointProblem, NonlinearSolver
from ..problems import IsospectralProblem
from ._base import Method, StepResult

__all__ = ["IsoMP"]

Array = NDArray[Any]


@dataclass(frozen=True)
class IsoMP(Method):
    """The isospectral minimal midpoint method.

    Parameters
    ----------
    solver : FixedPoint or Newton
        Nonlinear solver for the stage ``X`` (default: fixed-point iteration, tolerance
        ``1e-14 ||W_k||``).
    initial_guess : {"extrapolate", "state"}
        Starting point of the solve. ``"state"`` is ``X = W_k`` (the paper's). ``"extrapolate"``
        (default) reuses the previous step's stage offset, ``X = W_k + (X_{k-1} - W_{k-1})``,
        which is ``O(h^2)`` closer and saves iterations; the first step uses ``W_k``.

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

    order: ClassVar[int] = 2
    implicit: ClassVar[bool] = True
    name: ClassVar[str] = "IsoMP"

    def __post_init__(self) -> None:
        if self.initial_guess not in ("extrapolate", "state"):
            raise ValueError(
                f"initial_guess must be 'extrapolate' or 'state', got {self.initial_guess!r}"
            )
        if not isinstance(self.solver, NonlinearSolver):
            raise TypeError(f"solver must be FixedPoint() or Newton(), got {self.solver!r}")

    def stage_problem(self, problem: IsospectralProblem, W: Array, h: float) -> FixedPointProblem:
        """The fixed-point problem ``X = G(X)`` of one step from ``W``."""
        alg = problem.algebra
        stage_alg = alg.stage_algebra
        half, quarter = 0.5 * h, 0.25 * h * h

        def G(X: Array, mask: Array | None) -> tuple[Array, Array]:
            Wm = W if mask is None else W[mask]
            C, T = alg.bracket_and_triple(problem.evaluate_B(X), X)
            return stage_alg.project(Wm + half * C + quarter * T), C

        jvp = None
        if problem.B_jvp is not None:

            def jvp(X: Array, dX: Array, mask: Array | None) -> Array:
                B = problem.evaluate_B(X)
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

    def step(
        self, problem: IsospectralProblem, y: Array, h: float, state: Any = None
    ) -> StepResult:
        alg = problem.algebra
        X0 = y
        if self.initial_guess == "extrapolate" and state is not None and state[0] == h:
            X0 = y + state[1]
        res = self.solver.solve(self.stage_problem(problem, y, h), X0)
        y_next = alg.project(y + h * res.aux)
        new_state = (h, res.x - y) if self.initial_guess == "extrapolate" else None
        return StepResult(
            y=y_next,
            stage=res.x,
            iterations=res.iterations,
            residual=res.residual,
            status=res.status,
            state=new_state,
        )
