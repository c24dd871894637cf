"""Section 3.1 and 3.2 of the paper: the generalized rigid body on so(10) and Brockett's flow."""

from __future__ import annotations

import time

import numpy as np

from .. import models
from .._solve import solve
from ..methods import IsoMP
from ..nonlinear import FixedPoint, Newton
from ._common import ExperimentResult, check, header

__all__ = ["brockett", "rigid_body"]


def _solver(name: str, rtol: float) -> FixedPoint | Newton:
    if name == "newton":
        return Newton(rtol=rtol)
    if name == "fixed-point":
        return FixedPoint(rtol=rtol)
    raise ValueError(f"solver must be 'fixed-point' or 'newton', got {name!r}")


def rigid_body(
    *,
    n: int = 10,
    h: float = 0.1,
    T: float = 100.0,
    solver: str = "fixed-point",
    rtol: float = 1e-14,
    quick: bool = False,
    progress: bool | None = None,
) -> ExperimentResult:
    """Generalized rigid body on so(n) with IsoMP: Casimir and Hamiltonian variation in time.

    Paper, Sec. 3.1 (Fig. 1), with the symmetrized inertia of NOTES.md. ``quick`` integrates to
    ``T = 10``. Claims checked: Casimirs (eigenvalues) conserved to rounding; the Hamiltonian
    nearly conserved (bounded relative variation, ``O(h^2)``).

    Returns
    -------
    ExperimentResult
        ``data``: ``ts``, ``casimir_variation`` ``(n_save, m)`` (``C(t) - C(0)``),
        ``hamiltonian_variation`` ``(n_save,)`` (``H(t) - H(0)``).
    """
    T = 10.0 if quick else T
    params = {"n": n, "h": h, "T": T, "solver": solver, "rtol": rtol}
    problem, W0 = models.rigid_body(n=n)
    start = time.perf_counter()
    sol = solve(problem, IsoMP(solver=_solver(solver, rtol)), W0, dt=h, t1=T, progress=progress)
    wall = time.perf_counter() - start
    d = sol.diagnostics
    assert d is not None and d.hamiltonian is not None
    C = np.real(d.casimirs)
    s = d.summary()
    H0 = float(d.hamiltonian[0])
    summary = header("rigid-body", params, quick) | {
        "drifts": s,
        "steps": sol.stats.n_steps,
        "iterations_mean": sol.stats.iterations_mean,
        "timings": {"solve": wall, "per_step": wall / max(sol.stats.n_steps, 1)},
        "checks": {
            "casimirs_rounding": check(
                s["casimir_drift"], 1e-12, "Casimirs (eigenvalues) conserved to rounding"
            ),
            "distance_to_so_n": check(s["max_distance"], 1e-12, "the state stays in so(n)"),
            "hamiltonian_bounded": check(
                s["hamiltonian_relative_drift"], 1e-3, "Hamiltonian nearly conserved (O(h^2))"
            ),
        },
    }
    data = {
        "ts": sol.ts,
        "casimir_variation": C - C[:1],
        "hamiltonian_variation": d.hamiltonian - H0,
        "H0": H0,
    }
    summary["wall_time"] = time.perf_counter() - start
    return ExperimentResult("rigid-body", data, summary)


def brockett(
    *,
    n: int = 10,
    h: float = 0.1,
    T: float = 1000.0,
    seed: int = 0,
    save_every: int = 10,
    quick: bool = False,
    progress: bool | None = None,
) -> ExperimentResult:
    """Brockett's double bracket flow on herm(n), ``N = diag(1..n)``: eigenvalue variation.

    Paper, Sec. 3.2 (Fig. 2). ``quick`` integrates to ``T = 100``. Claims checked: eigenvalues
    conserved to rounding; ``Tr(WN)`` non-decreasing; ``W`` tends to a diagonal matrix with the
    eigenvalues in ascending order (the order of ``N``).

    Returns
    -------
    ExperimentResult
        ``data``: ``ts``, ``eigenvalue_variation`` ``(n_save, n)``, ``off_diagonal``
        (relative Frobenius norm of the off-diagonal part), ``diagonal`` (final diagonal),
        ``eigenvalues``.
    """
    T = 100.0 if quick else T
    params = {"n": n, "h": h, "T": T, "seed": seed, "save_every": save_every}
    problem, W0 = models.brockett(n=n, seed=seed)
    start = time.perf_counter()
    sol = solve(problem, IsoMP(), W0, dt=h, t1=T, save_every=save_every, progress=progress)
    wall = time.perf_counter() - start
    d = sol.diagnostics
    assert d is not None
    C = np.real(d.casimirs)
    W = sol.ys
    diag = np.real(np.einsum("tii->ti", W))
    off = np.linalg.norm(W - diag[:, :, None] * np.eye(n), axis=(1, 2)) / np.linalg.norm(
        W, axis=(1, 2)
    )
    eig = np.linalg.eigvalsh(W0)
    final_diag = diag[-1]
    s = d.summary()
    summary = header("brockett", params, quick) | {
        "drifts": s,
        "steps": sol.stats.n_steps,
        "iterations_mean": sol.stats.iterations_mean,
        "final_off_diagonal": float(off[-1]),
        "final_diagonal_minus_sorted_eigenvalues": float(np.max(np.abs(final_diag - eig))),
        "timings": {"solve": wall, "per_step": wall / max(sol.stats.n_steps, 1)},
        "checks": {
            "eigenvalues_rounding": check(
                s["casimir_drift"], 1e-12, "eigenvalues conserved to rounding"
            ),
            "trace_WN_monotone": check(
                s.get("lyapunov_max_decrease", 0.0), 1e-12, "Tr(WN) non-decreasing"
            ),
            "tends_to_diagonal": check(
                float(off[-1]), 1e-3 if quick else 1e-10, "W tends to a diagonal matrix"
            ),
            "ascending_order": check(
                float(np.max(np.abs(final_diag - eig))),
                1e-3 if quick else 1e-10,
                "the limit diagonal is the eigenvalues in ascending order",
            ),
        },
    }
    data = {
        "ts": sol.ts,
        "eigenvalue_variation": C - C[:1],
        "off_diagonal": off,
        "diagonal": final_diag,
        "eigenvalues": eig,
    }
    summary["wall_time"] = time.perf_counter() - start
    return ExperimentResult("brockett", data, summary)
