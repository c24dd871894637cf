"""The paper's experiments by name: :data:`EXPERIMENTS` and :func:`get_experiment`.

Listing the names imports nothing; :func:`get_experiment` imports the experiment's module
(which may load numba or matplotlib) on first use.
"""

from __future__ import annotations

import importlib
from typing import Any

from ._params import choice

__all__ = ["EXPERIMENTS", "get_experiment"]

#: The paper's experiments: name -> ``"module:attribute"`` of its
#: :class:`isoflow.experiments.Experiment` (imported by :func:`get_experiment`).
EXPERIMENTS: dict[str, str] = {
    name: f"isoflow.experiments.{name.replace('-', '_')}:{name.replace('-', '_')}"
    for name in (
        "rigid-body",
        "brockett",
        "spin-chain-cost",
        "spin-chain-energy",
        "spin-chain-error",
        "vortices-trajectories",
        "vortices-invariants",
        "euler-sphere",
        "mhd-sphere",
        "stochastic",
        "work-precision",
        "forced-turbulence",
        "qg-jets",
    )
}


def get_experiment(name: str) -> Any:
    """The :class:`isoflow.experiments.Experiment` called ``name``."""
    module, _, attr = EXPERIMENTS[choice(name, EXPERIMENTS, "experiment")].partition(":")
    return getattr(importlib.import_module(module), attr)
