r"""Parameter and initial-condition sweeps on a dask.distributed cluster.

A sweep is a model, a method, a time grid and a table of members (parameters and/or seeds, or
a grid of them). Members that differ only in their initial data are grouped into tasks, each
one batched :func:`isoflow.solve` (the compiled ensemble paths) in a dask worker, written to
its own resumable HDF5 file. ::

    import isoflow as iso
    res = iso.sweep.run("sweep.toml", "out/")      # a LocalCluster, one process per core
    ds = iso.sweep.open_sweep("out/")              # xarray, a ``member`` dimension, lazy

or ``isoflow sweep sweep.toml --out out/`` and ``isoflow info out/``. Running and reading
sweeps needs the extra ``pip install 'isoflow[sweep]'`` (dask, distributed, xarray), imported
only then (without it: one line :class:`MissingExtraError`).

The sweep file's keys, how members become tasks, the files of a sweep directory, faults and
resuming, clusters (local, an existing scheduler, SLURM), the limits and the exit statuses of
``isoflow sweep`` are described in the user guide's page on sweeps
(:doc:`/user_guide/sweeps`).

Modules: :mod:`~isoflow.sweep.spec` (reading and checking a sweep file, members, tasks),
:mod:`~isoflow.sweep.task` (one task in a worker), :mod:`~isoflow.sweep.submit` (:func:`run`),
:mod:`~isoflow.sweep.files` (the directory, manifest and summaries, each checked when read),
:mod:`~isoflow.sweep.results` (:func:`open_sweep`, :func:`status`).
"""

from __future__ import annotations

from .results import open_sweep, status
from .spec import (
    Member,
    MissingExtraError,
    SweepError,
    SweepSpec,
    Task,
    canonical_json,
    read_spec,
)
from .submit import SweepResult, run
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
    "run",
    "run_task",
    "status",
]
