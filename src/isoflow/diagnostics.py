r"""Invariant diagnostics on saved states: Casimirs, Hamiltonian, user invariants, distance to V.

All drifts are maxima over the saved times of the deviation from the first saved state:

* ``casimir_drift``: :math:`\max_t \max_j |C_j(t) - C_j(t_0)| / s_j`, with ``s_j`` the
  algebra's natural scale (``||W_0||`` for eigenvalues, ``||W_0||^k`` for ``Tr(W^k)``);
* ``hamiltonian_drift``: :math:`\max_t |H(t) - H(t_0)|` (absolute) and
  ``hamiltonian_relative_drift`` divided by :math:`\max(|H(t_0)|, \text{tiny})`;
* ``lyapunov_max_decrease``: :math:`\max_k \max(L(t_k) - L(t_{k+1}), 0)` for a function
  ``L`` that the exact flow never decreases (zero means monotone on the saved states);
* ``invariant_drift[name]``: :math:`\max_t \max |I(t) - I(t_0)|` (absolute);
* ``max_distance``: :math:`\max_t \operatorname{dist}(W(t), V)` (Frobenius, absolute).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .problems import IsospectralProblem

__all__ = ["Diagnostics", "compute_diagnostics"]

Array = NDArray[Any]


@dataclass(frozen=True)
class Diagnostics:
    """Time series of invariants on the saved states and their drifts (per ensemble member).

    Attributes
    ----------
    ts : ndarray, shape (n_save,)
    casimirs : ndarray, shape (n_save, *batch, m)
    casimir_drift : ndarray, shape batch
    distance : ndarray, shape (n_save, *batch)
    max_distance : ndarray, shape batch
    hamiltonian, hamiltonian_drift, hamiltonian_relative_drift : ndarray or None
    lyapunov, lyapunov_max_decrease : ndarray or None
    invariants, invariant_drift : dict
    """

    ts: Array
    casimirs: Array
    casimir_drift: Array
    distance: Array
    max_distance: Array
    hamiltonian: Array | None = None
    hamiltonian_drift: Array | None = None
    hamiltonian_relative_drift: Array | None = None
    lyapunov: Array | None = None
    lyapunov_max_decrease: Array | None = None
    invariants: dict[str, Array] = field(default_factory=dict)
    invariant_drift: dict[str, Array] = field(default_factory=dict)

    def summary(self) -> dict[str, float]:
        """Worst case over the ensemble of every drift, as plain floats (JSON-ready)."""
        out = {
            "casimir_drift": float(np.max(self.casimir_drift)),
            "max_distance": float(np.max(self.max_distance)),
        }
        if self.hamiltonian_drift is not None:
            out["hamiltonian_drift"] = float(np.max(self.hamiltonian_drift))
            assert self.hamiltonian_relative_drift is not None
            out["hamiltonian_relative_drift"] = float(np.max(self.hamiltonian_relative_drift))
        if self.lyapunov_max_decrease is not None:
            out["lyapunov_max_decrease"] = float(np.max(self.lyapunov_max_decrease))
        for name, d in self.invariant_drift.items():
            out[f"{name}_drift"] = float(np.max(d))
        return out


def _drift(series: Array, core: int) -> Array:
    dev = np.abs(series - series[:1])
    axes = (0, *range(dev.ndim - core, dev.ndim))
    return np.max(dev, axis=axes)


def compute_diagnostics(problem: IsospectralProblem, ts: Array, ys: Array) -> Diagnostics:
    """Diagnostics of the states ``ys`` (time-first, ``(n_save, *batch, *shape)``) at ``ts``."""
    alg = problem.algebra
    C = alg.casimirs(ys)
    scale = alg.casimir_scale(ys[0])
    casimir_drift = np.max(np.abs(C - C[:1]) / scale, axis=(0, C.ndim - 1))
    dist = alg.distance(ys)
    kw: dict[str, Any] = {}
    if problem.hamiltonian is not None:
        H = np.real(np.asarray(problem.hamiltonian(ys)))
        dH = np.max(np.abs(H - H[:1]), axis=0)
        kw.update(
            hamiltonian=H,
            hamiltonian_drift=dH,
            hamiltonian_relative_drift=dH / np.maximum(np.abs(H[0]), np.finfo(float).tiny),
        )
    if problem.lyapunov is not None:
        L = np.real(np.asarray(problem.lyapunov(ys)))
        dec = (
            np.max(np.maximum(L[:-1] - L[1:], 0.0), axis=0) if len(L) > 1 else np.zeros(L.shape[1:])
        )
        kw.update(lyapunov=L, lyapunov_max_decrease=dec)
    inv, inv_drift = {}, {}
    batch_nd = ys.ndim - 1 - alg.core_ndim
    for name, fn in problem.invariants.items():
        series = np.asarray(fn(ys))
        inv[name] = series
        inv_drift[name] = _drift(series, series.ndim - 1 - batch_nd)
    return Diagnostics(
        ts=ts,
        casimirs=C,
        casimir_drift=casimir_drift,
        distance=dist,
        max_distance=np.max(dist, axis=0),
        invariants=inv,
        invariant_drift=inv_drift,
        **kw,
    )
