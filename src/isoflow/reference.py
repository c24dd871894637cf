"""High-accuracy reference solutions with scipy's DOP853, for error measurements."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.integrate import solve_ivp

from ._errors import IsoflowError
from .problems import IsospectralProblem

__all__ = ["dop853", "reference_solution"]


def dop853(
    problem: IsospectralProblem,
    y0: ArrayLike,
    t_eval: ArrayLike,
    *,
    t0: float = 0.0,
    rtol: float = 1e-13,
    atol: float = 1e-13,
) -> tuple[NDArray[Any], int]:
    r"""``W`` at ``t_eval`` by scipy's DOP853 and the number of evaluations of the vector field.

    The state is integrated in its real flat representation as a generic ODE (no structure
    preserved), with adaptive steps at the tolerances given; one evaluation of the vector field
    :math:`[B(W), W]` is one evaluation of ``B`` (per member).

    Parameters
    ----------
    problem : IsospectralProblem
        The problem (its linear part, forcing and noise, if any, are not integrated: only
        :math:`[B(W), W]`).
    y0 : array_like, shape (*batch, *shape)
        The initial state at ``t0``, one member or an ensemble (checked to lie in the space).
    t_eval : array_like, shape (n_t,)
        The output times (increasing from ``t0``; the integration ends at the last one).
    t0 : float
        The initial time (default 0).
    rtol, atol : float
        Relative and absolute tolerances of DOP853 (default ``1e-13`` each).

    Returns
    -------
    W : ndarray, shape (n_t, *batch, *shape)
        The states at ``t_eval``.
    nfev : int
        The number of evaluations of the vector field.

    Raises
    ------
    IsoflowError
        The integration failed.
    """
    alg = problem.algebra
    W0 = alg.validate(y0, "y0")
    shape = W0.shape
    lead = shape[: W0.ndim - alg.core_ndim]
    t_eval = np.asarray(t_eval, dtype=float)

    def rhs(_t: float, v: NDArray[np.float64]) -> NDArray[np.float64]:
        W = alg._unflatten(v.reshape(*lead, -1))
        return alg._flatten(problem.vector_field(W)).ravel()

    v0 = alg._flatten(W0).ravel()
    sol = solve_ivp(
        rhs, (t0, float(t_eval[-1])), v0, method="DOP853", t_eval=t_eval, rtol=rtol, atol=atol
    )
    if not sol.success:
        raise IsoflowError(f"DOP853 solve failed: {sol.message}")
    out = [alg._unflatten(sol.y[:, i].reshape(*lead, -1)) for i in range(len(t_eval))]
    return np.stack(out), int(sol.nfev)


# The same keyword signature as dop853 on purpose: this is its public shorthand that drops
# the evaluation count.
def reference_solution(
    problem: IsospectralProblem,
    y0: ArrayLike,
    t_eval: ArrayLike,
    *,
    t0: float = 0.0,
    rtol: float = 1e-13,
    atol: float = 1e-13,
) -> NDArray[Any]:
    r"""Solve :math:`\dot W = [B(W), W]` with DOP853 and return ``W`` at ``t_eval``.

    The state (one member or an ensemble) is integrated in its real flat representation, as a
    generic ODE with no structure preserved: an independent check of the structure-preserving
    methods. Returns an array of shape ``(len(t_eval), *y0.shape)``.

    Parameters
    ----------
    problem : IsospectralProblem
        The problem (only :math:`[B(W), W]` is integrated).
    y0 : array_like, shape (*batch, *shape)
        The initial state at ``t0``.
    t_eval : array_like, shape (n_t,)
        The output times (the integration ends at the last one).
    t0 : float
        The initial time (default 0).
    rtol, atol : float
        Relative and absolute tolerances of DOP853 (default ``1e-13`` each).

    Returns
    -------
    ndarray, shape (n_t, *batch, *shape)

    Raises
    ------
    IsoflowError
        The integration failed.
    """
    return dop853(problem, y0, t_eval, t0=t0, rtol=rtol, atol=atol)[0]
