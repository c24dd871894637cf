"""Export of result files to xarray / netCDF, and full diagnostics of a loaded run.

The drift arithmetic lives in :mod:`isoflow.diagnostics` only (:class:`DiagnosticsAccumulator`);
this module feeds it the stored series.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._errors import IsoflowError, ResultFileError
from .._flags import check_flag
from ..diagnostics import Diagnostics, DiagnosticsAccumulator
from ..problems import IsospectralProblem
from .reader import RunData, load

__all__ = ["solution_diagnostics", "to_netcdf", "to_xarray"]

Array = NDArray[Any]


def to_xarray(path: str | os.PathLike[str]) -> Any:
    """The valid saved states and diagnostics of a result file as an :class:`xarray.Dataset`.

    Variables: ``y`` (or ``y_real``/``y_imag`` for complex states, so that netCDF can hold
    them) and the diagnostic series (``casimirs``, ``hamiltonian``, ``invariants_<name>``,
    ...). Dimensions: ``time`` first; for an ensemble its axes next, shared by every variable
    (``member`` for one axis, ``member_0``, ``member_1``, ... for more, as
    :func:`isoflow.sweep.open_sweep`); then each variable's own (``y_dim0``, ...,
    ``casimirs_dim0``, ...). Attributes (JSON strings): ``config``, ``meta``, ``run_info``
    (status, message and statistics of the call that ended the run; ``null`` if it was
    killed) and ``drifts``; ``isoflow_step``, the steps behind the last saved state.

    Parameters
    ----------
    path : str or Path
        A result file.
    """
    try:
        import xarray as xr
    except ImportError as exc:  # pragma: no cover - optional dependency
        raise IsoflowError("to_xarray needs xarray: pip install 'isoflow[xarray]'") from exc
    run = load(path)
    nbatch = len(run.batch_shape)
    members = ["member"] if nbatch == 1 else [f"member_{i}" for i in range(nbatch)]
    data_vars: dict[str, Any] = {}

    def add(name: str, arr: Array) -> None:
        own = (f"{name}_dim{i}" for i in range(arr.ndim - 1 - nbatch))
        dims = ("time", *members, *own)
        if np.iscomplexobj(arr):
            data_vars[f"{name}_real"] = (dims, arr.real)
            data_vars[f"{name}_imag"] = (dims, arr.imag)
        else:
            data_vars[name] = (dims, arr)

    add("y", run.ys)
    for name, arr in run.series.items():
        add(name.replace("/", "_"), arr)
    return xr.Dataset(
        data_vars,
        coords={"time": run.ts},
        attrs={
            "config": json.dumps(run.config),
            "meta": json.dumps(run.meta),
            "run_info": json.dumps(run.run_info),
            "drifts": json.dumps(run.drifts),
            "isoflow_step": run.step,
        },
    )


def to_netcdf(
    path: str | os.PathLike[str], out: str | os.PathLike[str], *, force: bool = False
) -> Path:
    """Export a result file to netCDF-4 (engine ``h5netcdf``); returns the output path.

    The file is written beside ``out`` and renamed over it, so a failed export leaves no half
    file. An existing ``out`` is replaced only with ``force`` (and only a regular file); the
    result file itself never.

    Raises
    ------
    ResultFileError
        ``out`` is the result file, or exists (without ``force``) or is not a regular file.
    """
    from .writer import check_target

    src, dst = Path(path), Path(out)
    if dst.exists() and src.exists() and os.path.samefile(src, dst):
        raise ResultFileError(f"{dst} is the result file being exported; choose another name")
    check_flag(force, "force")
    target = check_target(dst, force=force, resumable=False)  # an export is not a run
    if not target.parent.is_dir():  # not created: a mistyped path
        raise ResultFileError(f"{dst}: no directory {target.parent} to write it in")
    ds = to_xarray(path)
    tmp = target.with_name(f".{target.name}.partial")
    try:
        ds.to_netcdf(tmp, engine="h5netcdf")
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return dst


def solution_diagnostics(run: RunData, problem: IsospectralProblem) -> Diagnostics:
    """Full :class:`Diagnostics` (time series and drifts) of a loaded run for ``problem``."""
    acc = DiagnosticsAccumulator(problem)
    acc.set_first_state(run.ys[0])
    acc.absorb(run.ts, run.series)
    d = acc.result()
    return Diagnostics(
        ts=run.ts,
        casimirs=run.series["casimirs"],
        casimir_drift=d.casimir_drift,
        distance=run.series["distance"],
        max_distance=d.max_distance,
        hamiltonian=run.series.get("hamiltonian"),
        hamiltonian_drift=d.hamiltonian_drift,
        hamiltonian_relative_drift=d.hamiltonian_relative_drift,
        lyapunov=run.series.get("lyapunov"),
        lyapunov_max_decrease=d.lyapunov_max_decrease,
        invariants={k: run.series[f"invariants/{k}"] for k in d.invariants},
        invariant_drift=d.invariant_drift,
        observables={k: run.series[f"observables/{k}"] for k in d.observables},
        forced_or_dissipative=d.forced_or_dissipative,
        energy_changes=d.energy_changes,
    )
