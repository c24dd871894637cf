"""What every experiment shares: the :class:`Experiment` interface, its result, checks, fits."""

from __future__ import annotations

import time
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from .._version import __version__

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["Experiment", "ExperimentResult", "check", "fit_order", "header"]

Array = NDArray[Any]


@dataclass
class ExperimentResult:
    """What an experiment returns: plain data for plotting and a JSON-ready summary.

    Attributes
    ----------
    name : str
        The experiment's command-line name (e.g. ``"spin-chain-error"``).
    data : dict
        Arrays and numbers to plot (not written to JSON).
    summary : dict
        Parameters, measured drifts, fitted orders, timings and ``checks`` (JSON-ready).
    """

    name: str
    data: dict[str, Any]
    summary: dict[str, Any] = field(default_factory=dict)

    @property
    def passed(self) -> bool:
        """Whether every check in ``summary["checks"]`` holds."""
        return all(c["ok"] for c in self.summary.get("checks", {}).values())


class Experiment(ABC):
    """One of the paper's experiments: how to run it and how to draw it, in one object.

    A subclass sets :attr:`name` and :attr:`description` and writes :meth:`run` (keyword
    parameters with the paper's values as defaults, plus ``quick`` and ``progress``; no plotting)
    and :meth:`figure`. Calling the object runs it: ``iso.experiments.rigid_body(T=10)``.
    Adding an experiment is one module in :mod:`isoflow.experiments` and its name in
    :data:`isoflow.registry.EXPERIMENTS`.
    """

    #: Command-line name, e.g. ``"rigid-body"``.
    name: ClassVar[str]
    #: One line: the run and the claim it checks.
    description: ClassVar[str]

    @abstractmethod
    def run(self, *args: Any, **kwargs: Any) -> ExperimentResult:
        """Run the experiment (``quick=True``: a reduced version; ``progress``: a bar)."""

    @abstractmethod
    def figure(self, result: ExperimentResult) -> Figure:
        """The paper-style figure of a result of :meth:`run`."""

    def __call__(self, **kwargs: Any) -> ExperimentResult:
        return self.run(**kwargs)

    def __repr__(self) -> str:
        return f"<experiment {self.name!r}: {self.description}>"

    def _result(
        self, data: dict[str, Any], summary: dict[str, Any], start: float
    ) -> ExperimentResult:
        """The result, with the wall time since ``start`` (``time.perf_counter()``) recorded."""
        summary["wall_time"] = time.perf_counter() - start
        return ExperimentResult(self.name, data, summary)

    def _check_result(self, result: ExperimentResult) -> None:
        if result.name != self.name:
            raise ValueError(f"a result of {result.name!r}, not of {self.name!r}")


def check(value: float, bound: float, claim: str, *, below: bool = True) -> dict[str, Any]:
    """A JSON-ready check ``value <= bound`` (or ``>=`` when ``below=False``)."""
    v = float(value)
    ok = bool(np.isfinite(v) and (v <= bound if below else v >= bound))
    return {
        "value": v,
        "bound": float(bound),
        "relation": "<=" if below else ">=",
        "ok": ok,
        "claim": claim,
    }


def fit_order(hs: Array, errors: Array) -> float:
    """Least-squares slope of ``log(error)`` against ``log(h)`` over the finite, positive points.

    Parameters
    ----------
    hs : array_like
        Step sizes (positive).
    errors : array_like
        The errors at those step sizes; NaN, Inf, zero or negative errors are left out.

    Returns
    -------
    float
        The slope (the observed order), NaN with fewer than two points left.
    """
    hs, errors = np.asarray(hs, float), np.asarray(errors, float)
    ok = np.isfinite(errors) & (errors > 0)
    if np.count_nonzero(ok) < 2:
        return float("nan")
    slope = np.polyfit(np.log(hs[ok]), np.log(errors[ok]), 1)[0]
    return float(slope)


def header(name: str, parameters: dict[str, Any], quick: bool) -> dict[str, Any]:
    """The common head of a JSON summary: experiment name, library version, parameters."""
    return {
        "experiment": name,
        "isoflow_version": __version__,
        "quick": bool(quick),
        "parameters": parameters,
    }
