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

__all__ = ["Diagnostics", "DiagnosticsAccumulator", "compute_diagnostics"]

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


class DiagnosticsAccumulator:
    """Incremental :class:`Diagnostics` for streamed runs: bounded memory in the number of states.

    Feed the saved states chunk by chunk, in time order, to :meth:`update`; it returns the
    per-state series of the chunk (for a writer to store) and keeps only the first state's
    values, the last Lyapunov value and the running maxima. :meth:`result` gives the same drifts
    as :func:`compute_diagnostics` on all the states at once (up to the order of the ``max``).

    Parameters
    ----------
    problem : IsospectralProblem
    """

    def __init__(self, problem: IsospectralProblem) -> None:
        self.problem = problem
        self._first: dict[str, Any] | None = None
        self._last: dict[str, Any] = {}
        self._max: dict[str, Array] = {}
        self._lyap_last: Array | None = None
        self._scale: Array | None = None
        self._batch_nd: int | None = None
        self._t_first = self._t_last = float("nan")

    def series(self, ys: Array) -> dict[str, Array]:
        """Per-state diagnostic series of ``ys`` (time first): name -> array, time first."""
        alg = self.problem.algebra
        out: dict[str, Array] = {
            "casimirs": np.asarray(alg.casimirs(ys)),
            "distance": np.asarray(alg.distance(ys)),
        }
        if self.problem.hamiltonian is not None:
            out["hamiltonian"] = np.real(np.asarray(self.problem.hamiltonian(ys)))
        if self.problem.lyapunov is not None:
            out["lyapunov"] = np.real(np.asarray(self.problem.lyapunov(ys)))
        for name, fn in self.problem.invariants.items():
            out[f"invariants/{name}"] = np.asarray(fn(ys))
        return out

    def update(self, ts: Array, ys: Array) -> dict[str, Array]:
        """Absorb the states ``ys`` at ``ts``; return their series (see :meth:`series`)."""
        if self._scale is None and len(ys):
            self._scale = np.asarray(self.problem.algebra.casimir_scale(ys[0]))
            self._batch_nd = ys.ndim - 1 - self.problem.algebra.core_ndim
        s = self.series(ys)
        self.absorb(np.asarray(ts, dtype=float), s)
        return s

    def absorb(self, ts: Array, series: dict[str, Array]) -> None:
        """Absorb already computed series (e.g. read back from a file when resuming)."""
        if len(ts) == 0:
            return
        if self._first is None:
            if self._scale is None:
                raise ValueError("absorb() needs set_first_state() or update() first")
            self._first = {k: v[:1].copy() for k, v in series.items()}
            self._t_first = float(ts[0])
        self._t_last = float(ts[-1])
        self._last = {k: v[-1:].copy() for k, v in series.items()}
        first = self._first
        assert self._batch_nd is not None
        for name, v in series.items():
            if name == "casimirs":
                dev = np.max(np.abs(v - first[name]) / self._scale, axis=(0, v.ndim - 1))
            elif name == "distance":
                dev = np.max(v, axis=0)
            elif name == "lyapunov":
                prev = v[:1] if self._lyap_last is None else self._lyap_last
                L = np.concatenate([prev, v])
                dev = np.max(np.maximum(L[:-1] - L[1:], 0.0), axis=0)
                self._lyap_last = v[-1:].copy()
            elif name == "hamiltonian":
                dev = np.max(np.abs(v - first[name]), axis=0)
            else:
                core = v.ndim - 1 - self._batch_nd
                dev = _drift(np.concatenate([first[name], v]), core)
            self._max[name] = dev if name not in self._max else np.maximum(self._max[name], dev)

    def set_first_state(self, y0: Array) -> None:
        """Fix the Casimir scale from the first state (needed before :meth:`absorb`)."""
        self._scale = np.asarray(self.problem.algebra.casimir_scale(y0))
        self._batch_nd = y0.ndim - self.problem.algebra.core_ndim

    def result(self) -> Diagnostics:
        """Diagnostics with the drifts over every absorbed state.

        The time series it holds are those of the first and the last state only (the full series
        went to the writer).
        """
        if self._first is None:
            raise ValueError("no states absorbed yet")
        ts = np.array([self._t_first, self._t_last])
        two = {k: np.concatenate([self._first[k], self._last[k]]) for k in self._first}
        kw: dict[str, Any] = {}
        if "hamiltonian" in two:
            dH = self._max["hamiltonian"]
            kw.update(
                hamiltonian=two["hamiltonian"],
                hamiltonian_drift=dH,
                hamiltonian_relative_drift=dH
                / np.maximum(np.abs(self._first["hamiltonian"][0]), np.finfo(float).tiny),
            )
        if "lyapunov" in two:
            kw.update(lyapunov=two["lyapunov"], lyapunov_max_decrease=self._max["lyapunov"])
        names = [k.split("/", 1)[1] for k in two if k.startswith("invariants/")]
        return Diagnostics(
            ts=ts,
            casimirs=two["casimirs"],
            casimir_drift=self._max["casimirs"],
            distance=two["distance"],
            max_distance=self._max["distance"],
            invariants={n: two[f"invariants/{n}"] for n in names},
            invariant_drift={n: self._max[f"invariants/{n}"] for n in names},
            **kw,
        )
