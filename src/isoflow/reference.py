"""High-accuracy reference solutions with scipy's DOP853, for error measurements."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.integrate import solve_ivp

from ._errors import IsoflowError
from .problems import IsospectralProblem

__all__ = ["reference_solution"]


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
    """
    alg = problem.algebra
    W0 = alg.validate(y0, "y0")
    shape = W0.shape
    t_eval = np.asarray(t_eval, dtype=float)

    def rhs(_t: float, v: NDArray[np.float64]) -> NDArray[np.float64]:
        W = alg._unflatten(v.reshape(*shape[: W0.ndim - alg.core_ndim], -1))
        return alg._flatten(problem.vector_field(W)).ravel()

    v0 = alg._flatten(W0).ravel()
    sol = solve_ivp(
        rhs, (t0, float(t_eval[-1])), v0, method="DOP853", t_eval=t_eval, rtol=rtol, atol=atol
    )
    if not sol.success:
        raise IsoflowError(f"reference DOP853 solve failed: {sol.message}")
    out = [
        alg._unflatten(sol.y[:, i].reshape(*shape[: W0.ndim - alg.core_ndim], -1))
        for i in range(len(t_eval))
    ]
    return np.stack(out)
