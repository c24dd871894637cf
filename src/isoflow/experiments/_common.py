"""Shared pieces of the experiments: the result container and small numerical helpers."""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["ExperimentResult", "check", "fit_order", "header", "timer"]

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
    """Least-squares slope of ``log(error)`` against ``log(h)`` over the finite, positive points."""
    hs, errors = np.asarray(hs, float), np.asarray(errors, float)
    ok = np.isfinite(errors) & (errors > 0)
    if np.count_nonzero(ok) < 2:
        return float("nan")
    slope = np.polyfit(np.log(hs[ok]), np.log(errors[ok]), 1)[0]
    return float(slope)


@contextmanager
def timer(out: dict[str, float], key: str) -> Iterator[None]:
    """Add the wall time of the block to ``out[key]`` (seconds)."""
    start = time.perf_counter()
    try:
        yield
    finally:
        out[key] = out.get(key, 0.0) + time.perf_counter() - start


def header(name: str, parameters: dict[str, Any], quick: bool) -> dict[str, Any]:
    """The common head of a JSON summary: experiment name, library version, parameters."""
    from .. import __version__

    return {
        "experiment": name,
        "isoflow_version": __version__,
        "quick": bool(quick),
        "parameters": parameters,
    }
