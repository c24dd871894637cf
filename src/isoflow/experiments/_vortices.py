"""What the two point-vortex experiments (Sec. 3.4) share: the paper's runs and the geometry.

Both integrate the paper's two configurations with IsoMP on sl(2,R)^3 (the hyperbolic midpoint
method): configuration 1 (equilateral relative equilibrium) with ``h = 0.01`` to ``T = 10``
and configuration 2 (geodesic relative equilibrium) with ``h = 0.001`` to ``T = 1``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .. import models, registry
from .._solve import solve

__all__ = ["PAPER_RUNS", "geodesic", "lorentz", "paper_runs", "poincare_disk"]

_L = np.array([1.0, 1.0, -1.0])
#: (configuration, h, T) of the paper
PAPER_RUNS = ((1, 0.01, 10.0), (2, 0.001, 1.0))


def poincare_disk(w: Any) -> Any:
    """Points ``(x, y, z)`` of the upper sheet of ``x^2 + y^2 - z^2 = -1`` in the Poincaré disk."""
    w = np.asarray(w)
    return w[..., :2] / (1.0 + w[..., 2:3])


def lorentz(a: Any, b: Any) -> Any:
    """The Lorentz product ``a_x b_x + a_y b_y - a_z b_z`` over the last axis."""
    return np.sum(np.asarray(a) * _L * np.asarray(b), axis=-1)


def geodesic(p: Any, q: Any, *, extend: float = 0.0, num: int = 200) -> Any:
    """Points of the hyperbolic geodesic through ``p`` and ``q`` (hyperboloid coordinates).

    The segment from ``p`` to ``q`` is parametrized by ``s`` in ``[0, 1]``; ``extend`` adds that
    many hyperbolic lengths on both ends (to draw the whole geodesic through the points).
    """
    p, q = np.asarray(p, float), np.asarray(q, float)
    d = float(np.arccosh(max(-lorentz(p, q), 1.0)))
    u = (q - np.cosh(d) * p) / np.sinh(d)  # unit tangent at p, Lorentz-orthogonal to p
    s = np.linspace(-extend, d + extend, num)
    return np.cosh(s)[:, None] * p + np.sinh(s)[:, None] * u


def paper_runs(progress: bool | None, rtol: float) -> list[dict[str, Any]]:
    """The paper's two runs: states, invariant variations, drifts, timings."""
    out = []
    for config, h, T in PAPER_RUNS:
        problem, w0 = models.hyperbolic_vortices(config=config)
        method = registry.make_method("isomp", registry.make_solver("fixed-point", rtol=rtol))
        sol = solve(problem, method, w0, dt=h, t1=T, progress=progress)
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


def runs_parameters(rtol: float) -> dict[str, Any]:
    """The ``parameters`` of both experiments' summaries."""
    return {"runs": [{"config": c, "h": h, "T": T} for c, h, T in PAPER_RUNS], "rtol": rtol}
