"""The paper's numerical experiments (Section 3), as functions that return data.

Each experiment is a function ``name(*, quick=False, progress=None, **parameters)`` returning an
:class:`ExperimentResult` (plain arrays in ``data``, a JSON-ready ``summary`` with parameters,
library version, drifts, orders, timings and ``checks``); plotting is separate
(:mod:`isoflow.plotting`). So from Python::

    import isoflow as iso
    res = iso.experiments.spin_chain_error(exponents=(4, 5, 6, 7))
    print(res.summary["observed_order"])
    fig = iso.plotting.plot_experiment(res)

:func:`run_experiment` is what ``isoflow reproduce`` does for one experiment: run it, write the
figure (PNG, and PDF) and ``<name>.json`` into a directory.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from ._common import ExperimentResult, fit_order
from .euler_sphere import euler_sphere
from .matrix_flows import brockett, rigid_body
from .spin_chain import spin_chain_cost, spin_chain_energy, spin_chain_error
from .vortices import vortices_invariants, vortices_trajectories

__all__ = [
    "EXPERIMENTS",
    "ExperimentResult",
    "brockett",
    "euler_sphere",
    "fit_order",
    "rigid_body",
    "run_experiment",
    "spin_chain_cost",
    "spin_chain_energy",
    "spin_chain_error",
    "vortices_invariants",
    "vortices_trajectories",
]

#: command-line name -> experiment function
EXPERIMENTS: dict[str, Callable[..., ExperimentResult]] = {
    "rigid-body": rigid_body,
    "brockett": brockett,
    "spin-chain-cost": spin_chain_cost,
    "spin-chain-energy": spin_chain_energy,
    "spin-chain-error": spin_chain_error,
    "vortices-trajectories": vortices_trajectories,
    "vortices-invariants": vortices_invariants,
    "euler-sphere": euler_sphere,
}


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"not JSON-serializable: {type(obj).__name__}")


def _clean(obj: Any) -> Any:
    """Replace non-finite floats by ``None`` (strict JSON)."""
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_clean(v) for v in obj]
    if isinstance(obj, float | np.floating) and not np.isfinite(obj):
        return None
    return obj


def run_experiment(
    name: str,
    out: str | os.PathLike[str],
    *,
    quick: bool = False,
    pdf: bool = True,
    progress: bool | None = None,
) -> list[Path]:
    """Run experiment ``name`` and write ``<name>.png`` (and ``.pdf``) and ``<name>.json``.

    Returns the written paths. The JSON holds the experiment's summary plus ``"passed"`` (all
    its checks hold).
    """
    from ..plotting import plot_experiment, save

    if name not in EXPERIMENTS:
        raise KeyError(f"unknown experiment {name!r} (choose from {', '.join(EXPERIMENTS)})")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    res = EXPERIMENTS[name](quick=quick, progress=progress)
    fig = plot_experiment(res)
    files = [out / f"{name}.png"]
    if pdf:
        files.append(out / f"{name}.pdf")
    for f in files:
        save(fig, f)
    summary = dict(res.summary, passed=res.passed)
    path = out / f"{name}.json"
    path.write_text(json.dumps(_clean(summary), indent=2, default=_json_default) + "\n")
    return [*files, path]
