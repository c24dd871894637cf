r"""Weak quantities of an ensemble: means and variances of observables over its members.

A stochastic run is judged by expectations :math:`\mathbb E\, f(W(t))` (weak order is what
users report). :func:`ensemble_statistics` estimates them from the members of a
:class:`~isoflow.Solution` (an ensemble solved at once) or of a sweep opened with
:func:`isoflow.sweep.open_sweep`, with their standard errors; members that failed are left out
(and counted).

Examples
--------
>>> import numpy as np, isoflow as iso
>>> prob, W0 = iso.models.rigid_body(3, noise=0.3, noise_seed=1)
>>> sol = iso.solve(prob, iso.StochasticIsoMP(), np.stack([W0] * 16), dt=0.05, n_steps=20)
>>> est = iso.ensemble.ensemble_statistics(sol, prob.hamiltonian)
>>> est.mean.shape, est.members
((21,), 16)
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ._errors import ParameterError

__all__ = ["EnsembleEstimate", "ensemble_statistics"]

Array = NDArray[Any]


@dataclass(frozen=True)
class EnsembleEstimate:
    """Estimates over the members, per saved time.

    Attributes
    ----------
    times : ndarray, shape (n_times,)
    mean, variance, standard_error : ndarray, shape (n_times, *observable)
        The sample mean, the unbiased sample variance and the standard error of the mean
        :math:`\\sqrt{s^2 / M}`.
    members : int
        Members used (``M``).
    failed : int
        Members left out because they failed.
    """

    times: Array
    mean: Array
    variance: Array
    standard_error: Array
    members: int
    failed: int


def _members_first(source: Any) -> tuple[Array, Array, Array]:
    """``(times, states (M, n_times, *core), ok (M,))`` of a Solution or an open sweep."""
    if hasattr(source, "ys") and hasattr(source, "failed_step"):
        ys = np.asarray(source.ys)
        failed = np.asarray(source.failed_step).reshape(-1)
        M = failed.size
        if ys.ndim < 2 or M < 1 or int(np.prod(ys.shape[1:], dtype=np.int64)) % M:
            raise ParameterError("ensemble_statistics: the solution holds no ensemble")
        batch_ndim = np.asarray(source.failed_step).ndim
        core = ys.shape[1 + batch_ndim :]
        states = np.moveaxis(ys.reshape(ys.shape[0], M, *core), 1, 0)
        return np.asarray(source.ts), states, failed < 0
    if hasattr(source, "data_vars") and "y" in getattr(source, "data_vars", {}):
        states = np.asarray(source["y"].values)
        ok = np.asarray(source["status"].values) == "finished"
        return np.asarray(source["time"].values), states, ok
    raise ParameterError(
        "ensemble_statistics needs a Solution of an ensemble or a sweep from "
        f"iso.sweep.open_sweep, got {type(source).__name__}"
    )


def ensemble_statistics(
    source: Any, observable: Callable[[Array], Array] | None = None
) -> EnsembleEstimate:
    r"""Mean, variance and standard error of ``observable`` over the members, per saved time.

    Parameters
    ----------
    source : Solution or xarray.Dataset
        An ensemble's solution (``sol.ys`` of shape ``(n_times, *batch, *core)``), or a sweep
        opened with :func:`isoflow.sweep.open_sweep` (members that did not finish are left out).
    observable : callable, optional
        ``f(states)`` for states of shape ``(..., *core)``, returning ``(..., *observable)``
        (e.g. ``problem.hamiltonian``); default: the state itself. Complex values (the states
        of ``u(n)``, ``su(n)``, ``herm(n)``) give a complex mean and the variance of
        :math:`|x - \bar x|^2` (real).

    Raises
    ------
    ParameterError
        Not an ensemble, or fewer than two members left.
    """
    times, states, ok = _members_first(source)
    used = states[ok]
    if used.shape[0] < 2:
        raise ParameterError(
            f"ensemble_statistics needs at least two members that did not fail, got {used.shape[0]}"
        )
    values = np.asarray(observable(used) if observable is not None else used)
    if values.dtype.kind not in "biufc":
        raise ParameterError(
            f"ensemble_statistics: the observable gave non-numeric values ({values.dtype})"
        )
    if values.dtype.kind != "c":  # complex values (states of u(n), herm(n)) stay complex
        values = values.astype(np.float64)
    M = values.shape[0]
    mean = values.mean(axis=0)
    var = values.var(axis=0, ddof=1)
    return EnsembleEstimate(times, mean, var, np.sqrt(var / M), M, int((~ok).sum()))
