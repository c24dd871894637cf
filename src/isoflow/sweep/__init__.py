r"""Parameter and initial-condition sweeps on a dask.distributed cluster.

A sweep is a model, a method, a time grid and a table of members (parameters and/or seeds, or
a grid of them). Members that differ only in their initial data are grouped into tasks, each
one batched :func:`isoflow.solve` (the compiled ensemble paths) in a dask worker, written to
its own resumable HDF5 file. ::

    import isoflow as iso
    res = iso.sweep("sweep.toml", "out/")          # a LocalCluster, one process per core
    ds = iso.sweep.open_sweep("out/")              # xarray, a ``member`` dimension, lazy

or ``isoflow sweep sweep.toml --out out/`` and ``isoflow info out/``. The package itself is
callable (``iso.sweep(...)`` is :func:`isoflow.sweep.run.sweep`); running and reading sweeps
needs the extra ``pip install 'isoflow[sweep]'`` (dask, distributed, xarray), imported only
then (without it: one line :class:`MissingExtraError`).

The sweep file's keys, how members become tasks, the files of a sweep directory, faults and
resuming, clusters (local, an existing scheduler, SLURM), the limits and the exit statuses of
``isoflow sweep`` are described in the user guide's page on sweeps
(:doc:`/user_guide/sweeps`).

Modules: :mod:`~isoflow.sweep.spec` (reading and checking a sweep file, members, tasks),
:mod:`~isoflow.sweep.task` (one task in a worker), :mod:`~isoflow.sweep.run` (submitting),
:mod:`~isoflow.sweep.files` (the directory, manifest and summaries, each checked when read),
:mod:`~isoflow.sweep.results` (:func:`open_sweep`, :func:`status`).
"""

from __future__ import annotations

import sys
import types
from typing import Any

from .results import open_sweep, status
from .run import SweepResult, sweep
from .spec import (
    Member,
    MissingExtraError,
    SweepError,
    SweepSpec,
    Task,
    canonical_json,
    read_spec,
)
from .task import build_member, build_task, member_run, run_task

__all__ = [
    "Member",
    "MissingExtraError",
    "SweepError",
    "SweepResult",
    "SweepSpec",
    "Task",
    "build_member",
    "build_task",
    "canonical_json",
    "member_run",
    "open_sweep",
    "read_spec",
    "run_task",
    "status",
    "sweep",
]


class _CallableModule(types.ModuleType):
    """This package, callable as :func:`sweep`.

    ``isoflow.sweep`` is both the package (``iso.sweep.open_sweep``) and the function
    (``iso.sweep("sweep.toml", "out")``): the import system binds the package itself as the
    attribute ``sweep`` of ``isoflow`` whenever any ``isoflow.sweep.*`` module is imported (as
    a dask worker does), so a plain function attribute would be replaced; a callable module
    cannot be.
    """

    def __call__(self, *args: Any, **kwargs: Any) -> SweepResult:
        return sweep(*args, **kwargs)


sys.modules[__name__].__class__ = _CallableModule
