"""Section 3.4 of the paper: point vortices on the hyperbolic plane with the hyperbolic midpoint.

Both experiments integrate the paper's two configurations with IsoMP on sl(2,R)^3 (the hyperbolic
midpoint method): configuration 1 (equilateral relative equilibrium) with ``h = 0.01`` to
``T = 10`` and configuration 2 (geodesic relative equilibrium) with ``h = 0.001`` to ``T = 1``.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from .. import models
from .._solve import solve
from ..methods import IsoMP
from ..nonlinear import FixedPoint
from ._common import ExperimentResult, check, header

__all__ = ["geodesic", "poincare_disk", "vortices_invariants", "vortices_trajectories"]

_L = np.array([1.0, 1.0, -1.0])
#: (configuration, h, T) of the paper
PAPER_RUNS = ((1, 0.01, 10.0), (2, 0.001, 1.0))


def poincare_disk(w: Any) -> Any:
    """Points ``(x, y, z)`` of the upper sheet of ``x^2 + y^2 - z^2 = -1`` in the Poincaré disk."""
    w = np.asarray(w)
    return w[..., :2] / (1.0 + w[..., 2:3])


def _lorentz(a: Any, b: Any) -> Any:
    return np.sum(np.asarray(a) * _L * np.asarray(b), axis=-1)


def geodesic(p: Any, q: Any, *, extend: float = 0.0, num: int = 200) -> Any:
    """Points of the hyperbolic geodesic through ``p`` and ``q`` (hyperboloid coordinates).

    The segment from ``p`` to ``q`` is parametrized by ``s`` in ``[0, 1]``; ``extend`` adds that
    many hyperbolic lengths on both ends (to draw the whole geodesic through the points).
    """
    p, q = np.asarray(p, float), np.asarray(q, float)
    d = float(np.arccosh(max(-_lorentz(p, q), 1.0)))
    u = (q - np.cosh(d) * p) / np.sinh(d)  # unit tangent at p, Lorentz-orthogonal to p
    s = np.linspace(-extend, d + extend, num)
    return np.cosh(s)[:, None] * p + np.sinh(s)[:, None] * u


def _runs(quick: bool, progress: bool | None, rtol: float) -> list[dict[str, Any]]:
    out = []
    for config, h, T in PAPER_RUNS:
        problem, w0 = models.hyperbolic_vortices(config=config)
        sol = solve(problem, IsoMP(solver=FixedPoint(rtol=rtol)), w0, dt=h, t1=T, progress=progress)
        d = sol.diagnostics
        assert d is not None and d.hamiltonian is not None
        M = d.invariants["momentum"]
        out.append(
            {
                "config": config,
                "h": h,
                "T": T,
                "ts": sol.ts,
                "ys": sol.ys,
                "hamiltonian_variation": d.hamiltonian - d.hamiltonian[0],
                "momentum_variation": M - M[:1],
                "drifts": d.summary(),
                "wall": sol.stats.wall_time,
                "steps": sol.stats.n_steps,
            }
        )
    return out


def _orbit_measures(ys: Any, M0: Any) -> dict[str, float]:
    """How far each vortex is from a closed circle of a rigid rotation about the momentum.

    For a relative equilibrium turning about the (timelike) momentum ``M``, each vortex keeps
    its Lorentz product with ``M`` (its orbit is a closed circle) and all pairwise products (the
    shape). Also the number of turns each vortex makes around its orbit's centre.
    """
    c = _lorentz(ys, M0[None, None, :])
    g = np.einsum("tik,tjk->tij", ys * _L, ys)
    z = poincare_disk(ys)
    zc = z[..., 0] + 1j * z[..., 1]
    turns = []
    for i in range(ys.shape[1]):
        ang = np.unwrap(np.angle(zc[:, i] - zc[:, i].mean()))
        turns.append(float(abs(ang[-1] - ang[0]) / (2 * np.pi)))
    out: dict[str, Any] = {
        "circle_deviation": float(np.max(np.abs(c - c[:1]) / np.abs(c[:1]))),
        "shape_deviation": float(np.max(np.abs(g - g[:1]))),
        "turns": turns,
    }
    return out


def vortices_trajectories(
    *, rtol: float = 1e-14, quick: bool = False, progress: bool | None = None
) -> ExperimentResult:
    """Vortex trajectories in the Poincaré disk, with the initial triangle / geodesic.

    Paper, Sec. 3.4 (Fig. 6). The runs are cheap, so ``quick`` changes nothing. Claims checked:
    configuration 1 stays a rigidly rotating equilateral relative equilibrium, every vortex on a
    closed circle (relative deviation of its Lorentz product with the momentum below ``1e-5``);
    every state stays on the hyperboloid to rounding.

    Returns
    -------
    ExperimentResult
        ``data["runs"]``: per configuration ``config, h, T, ts, disk`` (``(n_save, 3, 2)``
        Poincaré-disk trajectories), ``outline`` (disk points of the initial triangle or
        geodesic).
    """
    start = time.perf_counter()
    runs = _runs(quick, progress, rtol)
    data_runs, per_run, checks = [], {}, {}
    for r in runs:
        ys, w0 = r["ys"], r["ys"][0]
        problem, _ = models.hyperbolic_vortices(config=r["config"])
        M0 = r["momentum_variation"][0] + problem.invariants["momentum"](w0)
        meas = _orbit_measures(ys, np.asarray(M0))
        if r["config"] == 1:
            outline = np.concatenate([geodesic(w0[i], w0[(i + 1) % 3]) for i in range(3)])
        else:
            # the geodesic through the two outermost vortices (the three lie on it)
            dist = -_lorentz(w0[:, None, :], w0[None, :, :])
            i, j = np.unravel_index(np.argmax(dist), dist.shape)
            outline = geodesic(w0[i], w0[j], extend=6.0, num=400)
        data_runs.append(
            {
                "config": r["config"],
                "h": r["h"],
                "T": r["T"],
                "ts": r["ts"],
                "disk": poincare_disk(ys),
                "outline": poincare_disk(outline),
            }
        )
        per_run[f"config{r['config']}"] = {
            "h": r["h"],
            "T": r["T"],
            "steps": r["steps"],
            "solve_time": r["wall"],
            "hyperboloid_drift": r["drifts"]["casimir_drift"],
            **meas,
        }
        checks[f"config{r['config']}_on_hyperboloid"] = check(
            r["drifts"]["casimir_drift"], 1e-12, "vortices stay on the hyperboloid (rounding)"
        )
    checks["config1_closed_circles"] = check(
        per_run["config1"]["circle_deviation"],
        1e-5,
        "configuration 1: every vortex on a closed circle (rigid rotation)",
    )
    checks["config1_rigid_shape"] = check(
        per_run["config1"]["shape_deviation"],
        1e-5,
        "configuration 1: the equilateral shape is kept (relative equilibrium)",
    )
    summary = header(
        "vortices-trajectories",
        {"runs": [{"config": c, "h": h, "T": T} for c, h, T in PAPER_RUNS], "rtol": rtol},
        quick,
    ) | {"runs": per_run, "checks": checks}
    summary["wall_time"] = time.perf_counter() - start
    return ExperimentResult("vortices-trajectories", {"runs": data_runs}, summary)


def vortices_invariants(
    *, rtol: float = 1e-14, quick: bool = False, progress: bool | None = None
) -> ExperimentResult:
    """Momentum and Hamiltonian variation in time for the two vortex runs.

    Paper, Sec. 3.4 (Fig. 7). Claims checked: the momentum ``M = sum Gamma_i w_i`` conserved to
    rounding; the Hamiltonian nearly conserved (relative variation below ``1e-2``).

    Returns
    -------
    ExperimentResult
        ``data["runs"]``: per configuration ``config, h, T, ts, momentum_variation``
        ``(n_save, 3)``, ``hamiltonian_variation`` ``(n_save,)``.
    """
    start = time.perf_counter()
    runs = _runs(quick, progress, rtol)
    per_run, checks = {}, {}
    for r in runs:
        key = f"config{r['config']}"
        per_run[key] = {
            "h": r["h"],
            "T": r["T"],
            "steps": r["steps"],
            "solve_time": r["wall"],
            "drifts": r["drifts"],
        }
        checks[f"{key}_momentum_rounding"] = check(
            r["drifts"]["momentum_drift"], 1e-12, "momentum conserved to rounding"
        )
        checks[f"{key}_hamiltonian_bounded"] = check(
            r["drifts"]["hamiltonian_relative_drift"], 1e-2, "Hamiltonian nearly conserved"
        )
    data_runs = [
        {k: r[k] for k in ("config", "h", "T", "ts", "momentum_variation", "hamiltonian_variation")}
        for r in runs
    ]
    summary = header(
        "vortices-invariants",
        {"runs": [{"config": c, "h": h, "T": T} for c, h, T in PAPER_RUNS], "rtol": rtol},
        quick,
    ) | {"runs": per_run, "checks": checks}
    summary["wall_time"] = time.perf_counter() - start
    return ExperimentResult("vortices-invariants", {"runs": data_runs}, summary)
