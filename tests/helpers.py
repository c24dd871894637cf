"""Helpers shared by the tests: random problems and convergence-order fits."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

import isoflow as iso
from isoflow.algebras import Algebra

Array = NDArray[Any]


def loglog_slope(hs: Array, errors: Array) -> float:
    """Least-squares slope of ``log(error)`` against ``log(h)``."""
    return float(np.polyfit(np.log(np.asarray(hs)), np.log(np.asarray(errors)), 1)[0])


def linear_B_problem(alg: Algebra, seed: int = 0) -> iso.IsospectralProblem:
    """``B(W) = Pi_N(A W A^T + K)``-type linear map into the normalizer, seeded."""
    norm_alg = alg.normalizer
    rng = np.random.default_rng(seed)
    n = alg.shape[-1]
    A = rng.standard_normal((n, n)).astype(alg.dtype) / np.sqrt(n)
    K = norm_alg.random(rng, scale=0.3)

    def B(W: Array) -> Array:
        M = A @ W @ np.swapaxes(A, -1, -2)
        return norm_alg.project(M.astype(norm_alg.dtype, copy=False) if not norm_alg.is_complex else M) + K

    return iso.IsospectralProblem(B=B, algebra=alg, name=f"linear B on {alg.name}")


def nonlinear_B_problem(alg: Algebra, seed: int = 0) -> iso.IsospectralProblem:
    """A nonlinear ``B``: ``Pi_N(W^2 A + A W^2) + Pi_N(sin(W))``, seeded."""
    norm_alg = alg.normalizer
    rng = np.random.default_rng(seed)
    n = alg.shape[-1]
    A = rng.standard_normal((n, n)) / np.sqrt(n)

    def B(W: Array) -> Array:
        W2 = W @ W
        M = W2 @ A + A @ W2 + np.sin(W) + 0.5 * np.swapaxes(W, -1, -2)
        if not norm_alg.is_complex:
            M = np.real(M)
        return norm_alg.project(M)

    return iso.IsospectralProblem(B=B, algebra=alg, name=f"nonlinear B on {alg.name}")
