r"""Parameter and initial-condition sweeps on a dask.distributed cluster.

A sweep is a model, a method, a time grid and a table of members (parameters and/or seeds, or
a grid of them). Members that differ only in their initial data are grouped into tasks, each
one batched :func:`isoflow.solve` (the compiled ensemble paths) in a dask worker, written to
its own resumable HDF5 file. ::

    import isoflow as iso
    res = iso.sweep("sweep.toml", "out/")          # a LocalCluster, one process per core
    ds = iso.sweep.open_sweep("out/")              # xarray, a ``member`` dimension, lazy

or ``isoflow sweep sweep.toml --out out/`` and ``isoflow info out/``. This package (the module
itself is callable: ``iso.sweep(...)`` is :func:`isoflow.sweep.run.sweep`) needs the extra
``pip install 'isoflow[sweep]'`` (dask, distributed, xarray), imported only when a sweep runs.

The sweep file (TOML)
---------------------
::

    model = "rigid-body"          # any isoflow.registry model (or "package.module:function")
    method = "isomp"              # method, solver, rtol, anderson: as in `isoflow run`
    dt = 0.1                      # two of t1, dt, n_steps (the registry's rule); t0, save_every
    t1 = 100.0
    save_every = 10
    perturb = 1e-3                # optional: y0 <- project(y0 + eps |y0| R/|R|), R from the seed
    members_per_task = 32         # largest ensemble of one task (default 32)
    out = "rb-sweep"              # optional default of --out; chunk_rows, flush_seconds: as
                                  # in iso.io.HDF5Writer
    # initial = ["amp"]           # for a model of your own: parameters that only set y0

    [params]                      # shared by every member
    n = 10

    [grid]                        # the product of the columns ...
    seed = {start = 0, stop = 64}                  # integers like range (step optional)
    # amp = {start = 0.1, stop = 1.0, num = 10}    # numbers like linspace
    # J = [0.5, 1.0, 2.0]                          # or a list

    [[members]]                   # ... times each row (a row's own value wins over the grid)
    n = 8

Members are ``[[members]]`` rows times the product of the ``[grid]`` columns (with no rows, the
grid alone). ``seed`` is the model's own parameter where it has one (brockett, toda,
euler-sphere, ...), used as is; for a model without one (rigid-body) it chooses the random
perturbation and needs ``perturb`` (default seed: the member's index). A member may set
``t1``/``dt``/``n_steps`` (replacing the file's), but the time grid must be the same for all.
Unknown keys or parameters, wrong types, empty tables, duplicate members, ``seed`` without
``perturb``, a time grid that varies: one line :class:`SweepError` before anything runs.

Tasks and files
---------------
Members are grouped by their parameters without the initial-data ones
(:attr:`isoflow.registry.ModelSpec.initial`: seeds, amplitudes), in table order, and each group
split into ensembles of at most ``members_per_task``. A task is named by the first 20 hex digits
of the SHA-256 of the canonical JSON of the model, method, time grid, perturbation and its
members' parameters and seeds, so a changed sweep reuses the task files it shares with the old
one. The directory holds ``sweep.json`` (the manifest) and ``tasks/<id>.h5`` (the ensemble run,
:class:`isoflow.io.HDF5Writer`), ``tasks/<id>.json`` (the summary; its presence marks the task
done), ``tasks/<id>.log`` and ``tasks/<id>.lock`` (flock while a worker runs it).

Faults
------
* A member whose solve fails (diverges, no convergence, ``B`` raises) is recorded as
  ``failed`` with its step and reason; the other members of its ensemble and of the sweep
  finish.
* A task that raises is reported (``SweepResult.errors``, ``status`` ``"error"``); the other
  tasks finish; running the sweep again retries it.
* A worker that dies (killed, out of memory) costs only its task, which dask reruns on another
  worker (up to ``retries`` deaths, dask's ``distributed.scheduler.allowed-failures``); the
  rerun resumes the task's file from its last checkpoint, bit for bit.
* A sweep stopped at any moment (also ``kill -9`` of the client: the workers of its local
  cluster end with it) is resumed by running it again: done tasks are skipped, partial ones
  resumed with :func:`isoflow.io.resume`. Delete a summary (or a result file) to redo that task.

Clusters
--------
Default: a ``distributed.LocalCluster`` with one worker process per core, one thread each,
BLAS/OpenMP/numba pinned to one thread (``--workers K`` to choose). ``--scheduler
tcp://HOST:8786`` (``scheduler=``) attaches to any running scheduler; ``client=`` takes a
``distributed.Client``. The sweep directory must be on a file system the workers share, and
the workers need isoflow (and a model of your own) installed. On a SLURM cluster with
dask-jobqueue (``pip install dask-jobqueue``; this example is not run by the tests)::

    from dask_jobqueue import SLURMCluster
    from distributed import Client
    import isoflow as iso

    cluster = SLURMCluster(
        queue="normal", account="myproject",
        cores=32, processes=32, memory="64GB",     # one single-threaded worker per core
        walltime="02:00:00",
        job_script_prologue=["export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1",
                             "source ~/venvs/isoflow/bin/activate"],
    )
    cluster.scale(jobs=4)                          # 4 nodes, 128 workers
    with Client(cluster) as client:
        iso.sweep("sweep.toml", "/scratch/me/sweep", client=client)

(set ``distributed.scheduler.allowed-failures`` in the dask configuration for retries on such a
cluster). Results: :func:`open_sweep` gives one xarray Dataset over all task files.
"""

from __future__ import annotations

import sys
import types
from typing import Any

from .results import open_sweep, status
from .run import SweepResult, sweep
from .spec import Member, SweepError, SweepSpec, Task, canonical_json, read_spec
from .task import build_member, build_task, member_run, run_task

__all__ = [
    "Member",
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
