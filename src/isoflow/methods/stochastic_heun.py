r"""Stochastic Heun: the explicit Stratonovich baseline for transport noise (not isospectral).

For :math:`dW = [B(W), W]\,dt + \sum_i [B_i(W), W] \circ d\beta_i`
(:class:`isoflow.noise.TransportNoise`), one step with the increments :math:`\Delta\beta_i` is
the predictor–corrector

.. math::

    F(X) = \Big[h B(X) + \sum_i \Delta\beta_i B_i(X),\; X\Big], \qquad
    \bar W = W_k + F(W_k), \qquad
    W_{k+1} = W_k + \tfrac12 \big(F(W_k) + F(\bar W)\big),

the trapezoidal average that makes Euler's step consistent with the Stratonovich integral
(Kloeden and Platen, *Numerical Solution of Stochastic Differential Equations*, 1992; strong
order 1/2 for non-commuting noise, weak order 1). It is what spin-dynamics codes
run at finite temperature. Every step is a sum of brackets, so it stays in ``V``, but it is no
conjugation: the Casimirs (``|S_i|`` of spins, the spectrum of ``W``) drift by the local error,
:math:`O(h^{3/2})` a step, on every path (``reproduce stochastic`` compares the drift with the
stochastic midpoint's). It reads the same increments as :class:`isoflow.StochasticIsoMP`
(the same seed and truncation give the same Brownian path), on the NumPy path.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

from numpy.typing import NDArray

from ..noise import check_truncation
from ..problems import IsospectralProblem
from ._base import Method, StepDataRequest, StepResult
from .stochastic_isomp import check_substeps, step_increments, transport_increments

__all__ = ["StochasticHeun"]

Array = NDArray[Any]


@dataclass(frozen=True)
class StochasticHeun(Method):
    r"""The stochastic Heun method (explicit; strong order 1/2, weak order 1; not isospectral).

    Parameters
    ----------
    truncation : float or None
        As :class:`~isoflow.StochasticIsoMP` (default 2): the increments are the same.
    substeps : int
        As :class:`~isoflow.StochasticIsoMP` (default 1): steps on the Brownian path of a run
        with ``substeps`` times smaller steps.

    Examples
    --------
    >>> import isoflow as iso
    >>> prob, W0 = iso.models.rigid_body(3, noise=0.2, noise_seed=1)
    >>> sol = iso.solve(prob, iso.StochasticHeun(), W0, dt=0.01, n_steps=100, progress=False)
    >>> bool(1e-10 < sol.diagnostics.casimir_drift < 1e-3)
    True
    """

    truncation: float | None = 2.0
    substeps: int = 1

    order: ClassVar[int] = 1
    implicit: ClassVar[bool] = False
    symmetric: ClassVar[bool] = False
    name: ClassVar[str] = "stochastic Heun"
    reads_step_data: ClassVar[bool] = True
    integrates_noise: ClassVar[bool] = True

    def __post_init__(self) -> None:
        object.__setattr__(self, "truncation", check_truncation(self.truncation))
        check_substeps(self.substeps)

    def step_data(self, problem: IsospectralProblem, request: StepDataRequest) -> Array:
        """The increments ``(nsteps, members, D)`` (those of :class:`~isoflow.StochasticIsoMP`).

        Parameters
        ----------
        problem : IsospectralProblem
            The problem to advance.
        request : StepDataRequest
            The steps, the members and the step size the data are for.

        Returns
        -------
        ndarray, shape (nsteps, members, D)
        """
        return transport_increments(problem, request, self.truncation, self.substeps)

    def step(
        self, problem: IsospectralProblem, y: Array, h: float, state: Any = None,
        data: Array | None = None,
    ) -> StepResult:  # fmt: skip
        """One stochastic Heun step on ``[h B(X) + sum_i dbeta_i B_i(X), X]``, projected.

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
        data : ndarray, shape (*batch, D), optional
            The step's Brownian increments, as the time loop hands them (:meth:`step_data`);
            ``None`` draws those of the first step of the members ``0 .. M - 1`` (a step on its
            own).

        Returns
        -------
        StepResult
            The new state.
        """
        alg = problem.algebra
        noise = problem.noise
        db = None if noise is None else step_increments(self, problem, y, h, data)

        def flow(X: Array) -> Array:
            """``F(X) = [h B(X) + sum_i dbeta_i B_i(X), X]``."""
            Bt = h * problem.evaluate_B(X)
            if db is not None:
                Bt = Bt + noise.increment(X, db, alg)  # type: ignore[union-attr]
            return alg.project(alg.bracket(Bt, X))

        F0 = flow(y)
        return StepResult(y=alg.project(y + 0.5 * (F0 + flow(y + F0))))
