"""The paper's numerical experiments (Section 3): each one object with its run and its figure.

An experiment is an :class:`Experiment` (one module each): ``run(quick=..., progress=...,
**parameters)`` returns an :class:`ExperimentResult` (plain arrays in ``data``, a JSON-ready
``summary`` with parameters, library version, drifts, orders, timings and ``checks``), and
``figure(result)`` draws it. Calling the object runs it::

    import isoflow as iso
    res = iso.experiments.spin_chain_error(exponents=(4, 5, 6, 7))
    print(res.summary["observed_order"])
    fig = iso.experiments.spin_chain_error.figure(res)

:func:`run_experiment` is what ``isoflow reproduce`` does for one experiment: run it, write the
figure (PNG, and PDF) and ``<name>.json`` into a directory. The names are those of
:data:`isoflow.registry.EXPERIMENTS`; adding an experiment is one module here and one line
there.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from .. import registry
from .._figures import save
from ._base import Experiment, ExperimentResult, fit_order
from .brockett import brockett as brockett
from .euler_sphere import euler_sphere as euler_sphere
from .mhd_sphere import mhd_sphere as mhd_sphere
from .rigid_body import rigid_body as rigid_body
from .spin_chain_cost import spin_chain_cost as spin_chain_cost
from .spin_chain_energy import spin_chain_energy as spin_chain_energy
from .spin_chain_error import spin_chain_error as spin_chain_error
from .stochastic import stochastic as stochastic
from .vortices_invariants import vortices_invariants as vortices_invariants
from .vortices_trajectories import vortices_trajectories as vortices_trajectories
from .work_precision import work_precision as work_precision

__all__ = [
    "EXPERIMENTS",
    "Experiment",
    "ExperimentResult",
    "brockett",
    "euler_sphere",
    "figure",
    "fit_order",
    "mhd_sphere",
    "rigid_body",
    "run_experiment",
    "spin_chain_cost",
    "spin_chain_energy",
    "spin_chain_error",
    "stochastic",
    "vortices_invariants",
    "vortices_trajectories",
    "work_precision",
]

#: Command-line name -> experiment, in the order of :data:`isoflow.registry.EXPERIMENTS`.
EXPERIMENTS: dict[str, Experiment] = {
    name: registry.get_experiment(name) for name in registry.EXPERIMENTS
}


def figure(result: ExperimentResult) -> Any:
    """The figure of a result of any experiment (dispatch on ``result.name``)."""
    if result.name not in EXPERIMENTS:
        raise ValueError(f"no experiment called {result.name!r}")
    return EXPERIMENTS[result.name].figure(result)


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

    Files of an earlier run in ``out`` are replaced (regular files only). Returns the written
    paths. The JSON holds the experiment's summary plus ``"passed"`` (all its checks hold).

    Parameters
    ----------
    name : str
        A registered experiment (``isoflow list experiments``).
    out : str or os.PathLike
        The output directory (created if missing).
    quick : bool
        Run the reduced version (default ``False``: the paper's parameters).
    pdf : bool
        Also write ``<name>.pdf`` (default ``True``).
    progress : bool or None
        Show progress bars (``None``, the default: only when the output is a terminal).

    Returns
    -------
    list of Path
        The figure files, then the JSON file.

    Raises
    ------
    FileExistsError
        ``<name>.json`` exists and is not a regular file.
    """
    experiment = registry.get_experiment(name)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    res = experiment.run(quick=quick, progress=progress)
    fig = experiment.figure(res)
    files = [out / f"{name}.png"]
    if pdf:
        files.append(out / f"{name}.pdf")
    for f in files:
        save(fig, f, force=True)
    summary = dict(res.summary, passed=res.passed)
    path = out / f"{name}.json"
    if path.exists() and not path.is_file():
        raise FileExistsError(f"{path} exists and is not a regular file; not replacing it")
    path.write_text(json.dumps(_clean(summary), indent=2, default=_json_default) + "\n")
    return [*files, path]
