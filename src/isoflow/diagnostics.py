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

A problem's ``observables`` (spectra, budget rates, quantities that a forcing or a dissipation
changes) are saved and returned as series, with no drift.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ._errors import InvalidBError
from .problems import IsospectralProblem

__all__ = [
    "Diagnostics",
    "DiagnosticsAccumulator",
    "DriftAccumulator",
    "compute_diagnostics",
    "series",
]

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
    observables : dict
        The series of the problem's observables (no drift: they are not conserved).
    forced_or_dissipative : bool
        The problem's linear part or forcing changes the Casimirs and the energy by design
        (their "drifts" are then changes, not errors).
    energy_changes : bool
        The flow may change the energy and the invariants other than the Casimirs by design
        (:attr:`isoflow.IsospectralProblem.energy_changes`: forcing, noise, or a dissipation in
        ``B``); their "drifts" are then changes.
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
    observables: dict[str, Array] = field(default_factory=dict)
    forced_or_dissipative: bool = False
    energy_changes: bool = False

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


def series_names(problem: IsospectralProblem) -> list[str]:
    """The names of the series :func:`series` computes for ``problem`` (a result file's
    ``diagnostics`` datasets)."""
    names = ["casimirs", "distance"]
    names += [k for k in ("hamiltonian", "lyapunov") if getattr(problem, k) is not None]
    names += [f"invariants/{k}" for k in problem.invariants]
    names += [f"observables/{k}" for k in problem.observables]
    return names


def series(problem: IsospectralProblem, ys: Array) -> dict[str, Array]:
    """Per-state diagnostic series of the states ``ys`` (time first): name -> array.

    ``casimirs``, ``distance`` and, where the problem has them, ``hamiltonian``,
    ``lyapunov``, ``invariants/<name>`` and ``observables/<name>``; each time first,
    ``(n, *batch, ...)``.

    Raises
    ------
    InvalidBError
        A ``hamiltonian``, ``lyapunov`` or invariant that returns something that is not a
        real numeric array of the states' batch shape (for the scalar ones).
    """
    alg = problem.algebra
    batch = ys.shape[: ys.ndim - alg.core_ndim]
    out: dict[str, Array] = {
        "casimirs": np.asarray(alg.casimirs(ys)),
        "distance": np.asarray(alg.distance(ys)),
    }
    for name, fn in (("hamiltonian", problem.hamiltonian), ("lyapunov", problem.lyapunov)):
        if fn is not None:
            out[name] = _user_series(fn, ys, name, batch, scalar=True)
    for name, fn in problem.invariants.items():
        out[f"invariants/{name}"] = _user_series(fn, ys, f"invariant {name!r}", batch)
    for name, fn in problem.observables.items():
        out[f"observables/{name}"] = _user_series(fn, ys, f"observable {name!r}", batch)
    return out


def _user_series(
    fn: Any, ys: Array, what: str, batch: tuple[int, ...], scalar: bool = False
) -> Array:
    """``fn(ys)`` checked: numeric, leading axes ``batch``, real (the real part of a complex
    value is taken for the scalar functions, as for ``Tr`` forms)."""
    try:
        v = np.asarray(fn(ys))
    except Exception as exc:
        raise InvalidBError(f"the problem's {what} raised {type(exc).__name__}: {exc}") from exc
    if v.dtype.kind not in "biufc":
        raise InvalidBError(f"the problem's {what} returned non-numeric values ({v.dtype})")
    if v.shape[: len(batch)] != batch or (scalar and v.shape != batch):
        want = f"{batch}" if scalar else f"({', '.join(map(str, batch))}, ...)"
        raise InvalidBError(
            f"the problem's {what} returned shape {v.shape} for states of shape {ys.shape}; "
            f"expected {want}"
        )
    if scalar:
        v = np.real(v)
    return v.astype(np.float64) if v.dtype.kind in "biu" else v


class DriftAccumulator:
    """The drifts of diagnostic series absorbed chunk by chunk: the one drift implementation.

    Used by :class:`DiagnosticsAccumulator` (runs) and by the readers of result files, which
    absorb the stored series. Keeps the first state's values, the last Lyapunov value and the
    running maxima; memory does not grow with the number of states.

    Parameters
    ----------
    casimir_scale : array_like
        Per-member, per-component scale of the Casimirs (:meth:`Algebra.casimir_scale` of the
        first state), to make their drift relative.
    batch_ndim : int
        Number of ensemble axes of the states.
    """

    def __init__(self, casimir_scale: Any, batch_ndim: int) -> None:
        self.scale = np.asarray(casimir_scale, dtype=float)
        self.batch_ndim = int(batch_ndim)
        self.first: dict[str, Array] | None = None
        self.last: dict[str, Array] = {}
        self.max: dict[str, Array] = {}
        self._lyap_last: Array | None = None
        self.t_first = self.t_last = float("nan")
        self.count = 0

    def absorb(self, ts: Array, series: dict[str, Array]) -> None:
        """Absorb the series of the states at ``ts`` (time first, in time order)."""
        ts = np.asarray(ts, dtype=float)
        if len(ts) == 0:
            return
        if self.first is None:
            self.first = {k: np.array(v[:1], copy=True) for k, v in series.items()}
            self.t_first = float(ts[0])
        self.t_last = float(ts[-1])
        self.count += len(ts)
        self.last = {k: np.array(v[-1:], copy=True) for k, v in series.items()}
        first = self.first
        for name, v in series.items():
            if name.startswith("observables/"):  # not conserved: no drift
                continue
            if name == "casimirs":
                dev = np.max(np.abs(v - first[name]) / self.scale, axis=(0, v.ndim - 1))
            elif name == "distance":
                dev = np.max(v, axis=0)
            elif name == "lyapunov":
                prev = v[:1] if self._lyap_last is None else self._lyap_last
                L = np.concatenate([prev, v])
                dev = np.max(np.maximum(L[:-1] - L[1:], 0.0), axis=0)
                self._lyap_last = np.array(v[-1:], copy=True)
            else:
                dev = np.abs(v - first[name])
                core = dev.ndim - 1 - self.batch_ndim
                dev = np.max(dev, axis=(0, *range(dev.ndim - core, dev.ndim)))
            self.max[name] = dev if name not in self.max else np.maximum(self.max[name], dev)

    def drifts(self) -> dict[str, Array]:
        """Per-member drifts: ``casimir_drift``, ``max_distance``, ``hamiltonian_drift``,
        ``hamiltonian_relative_drift``, ``lyapunov_max_decrease``, ``<name>_drift``."""
        if self.first is None:
            raise ValueError("no states absorbed yet")
        out: dict[str, Array] = {}
        for name, d in self.max.items():
            key = {
                "casimirs": "casimir_drift",
                "distance": "max_distance",
                "hamiltonian": "hamiltonian_drift",
                "lyapunov": "lyapunov_max_decrease",
            }.get(name, f"{name.split('/', 1)[-1]}_drift")
            out[key] = d
        if "hamiltonian" in self.max:
            h0 = np.abs(self.first["hamiltonian"][0])
            out["hamiltonian_relative_drift"] = self.max["hamiltonian"] / np.maximum(
                h0, np.finfo(float).tiny
            )
        return out


class DiagnosticsAccumulator:
    """Incremental :class:`Diagnostics` for runs: series per chunk, drifts accumulated.

    Feed the saved states chunk by chunk, in time order, to :meth:`update`; it returns the
    per-state series of the chunk (for a writer to store). :meth:`result` gives the drifts over
    every state absorbed and, with ``keep_series=True``, the full time series (else those of
    the first and the last state only, as for a run streamed to a file).

    Parameters
    ----------
    problem : IsospectralProblem
    keep_series : bool
        Keep every chunk's series for :meth:`result`.
    """

    def __init__(self, problem: IsospectralProblem, keep_series: bool = False) -> None:
        self.problem = problem
        self.keep_series = keep_series
        self.drift: DriftAccumulator | None = None
        self._ts: list[Array] = []
        self._series: list[dict[str, Array]] = []

    def set_first_state(self, y0: Array) -> None:
        """Fix the Casimir scale from the first state (needed before :meth:`absorb`).

        Parameters
        ----------
        y0 : ndarray, shape (*batch, *shape)
            The first state of the run (drifts are relative to its Casimir scale).
        """
        alg = self.problem.algebra
        self.drift = DriftAccumulator(alg.casimir_scale(y0), y0.ndim - alg.core_ndim)

    def update(self, ts: Array, ys: Array) -> dict[str, Array]:
        """Absorb the states ``ys`` at ``ts``; return their series (see :func:`series`)."""
        if self.drift is None and len(ys):
            self.set_first_state(ys[0])
        s = series(self.problem, ys)
        self.absorb(np.asarray(ts, dtype=float), s)
        return s

    def absorb(self, ts: Array, s: dict[str, Array]) -> None:
        """Absorb already computed series (e.g. read back from a file when resuming).

        Parameters
        ----------
        ts : ndarray, shape (n,)
            Times of the states.
        s : dict of str to ndarray
            Their series, as :meth:`update` returns them (name to array ``(n, ...)``).

        Raises
        ------
        ValueError
            Called before :meth:`set_first_state` or :meth:`update`.
        """
        if self.drift is None:
            raise ValueError("absorb() needs set_first_state() or update() first")
        self.drift.absorb(ts, s)
        if self.keep_series and len(ts):
            self._ts.append(np.asarray(ts, dtype=float))
            self._series.append(s)

    def result(self) -> Diagnostics:
        """The :class:`Diagnostics` of every absorbed state (see the class docstring)."""
        acc = self.drift
        if acc is None or acc.first is None:
            raise ValueError("no states absorbed yet")
        if self.keep_series:
            ts = np.concatenate(self._ts)
            full = {k: np.concatenate([c[k] for c in self._series]) for k in self._series[0]}
        else:
            ts = np.array([acc.t_first, acc.t_last])
            full = {k: np.concatenate([acc.first[k], acc.last[k]]) for k in acc.first}
        d = acc.drifts()
        kw: dict[str, Any] = {}
        if "hamiltonian" in full:
            kw.update(
                hamiltonian=full["hamiltonian"],
                hamiltonian_drift=d["hamiltonian_drift"],
                hamiltonian_relative_drift=d["hamiltonian_relative_drift"],
            )
        if "lyapunov" in full:
            kw.update(lyapunov=full["lyapunov"], lyapunov_max_decrease=d["lyapunov_max_decrease"])
        names = [k.split("/", 1)[1] for k in full if k.startswith("invariants/")]
        observed = [k.split("/", 1)[1] for k in full if k.startswith("observables/")]
        return Diagnostics(
            ts=ts,
            casimirs=full["casimirs"],
            casimir_drift=d["casimir_drift"],
            distance=full["distance"],
            max_distance=d["max_distance"],
            invariants={n: full[f"invariants/{n}"] for n in names},
            invariant_drift={n: d[f"{n}_drift"] for n in names},
            observables={n: full[f"observables/{n}"] for n in observed},
            forced_or_dissipative=self.problem.forced_or_dissipative,
            energy_changes=self.problem.energy_changes,
            **kw,
        )


def compute_diagnostics(problem: IsospectralProblem, ts: Array, ys: Array) -> Diagnostics:
    """Diagnostics of the states ``ys`` (time-first, ``(n_save, *batch, *shape)``) at ``ts``.

    Parameters
    ----------
    problem : IsospectralProblem
        The problem the states belong to (its space, Hamiltonian, invariants, observables).
    ts : ndarray, shape (n_save,)
        The times.
    ys : ndarray, shape (n_save, *batch, *shape)
        The states, time first; drifts are relative to the first.

    Returns
    -------
    Diagnostics
        With the full time series.
    """
    acc = DiagnosticsAccumulator(problem, keep_series=True)
    acc.update(ts, ys)
    return acc.result()
