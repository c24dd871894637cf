"""Benchmark 14: a sweep on dask.distributed, 2 local workers against 1, and the cost per task.

64 tasks, each a CPU-bound ensemble of so(10) rigid bodies (perturbed initial states), run by
:func:`isoflow.sweep` on a ``LocalCluster`` of 2 single-threaded worker processes and of 1.
Target: speed-up >= 1.7. Then the scheduling overhead per task on 1 worker: 64 tasks of one
step each, the sweep's wall time less the time the tasks spent inside the worker (their
``task_seconds``: model built, ensemble solved, HDF5 file and summary written), per task,
against a 1-second task. Target: <= 5 %. The whole one-step task (files included) is reported
too. The workers are started
and warmed (numba loaded, the compiled loop run) before anything is timed; each timed sweep
writes a fresh directory. On a machine shared with other work the speed-up is bounded by what
two processes get at all: ``machine_speedup_2_processes`` (two pure-Python loops in two
processes against one, measured right after) and ``concurrency_2_workers`` (tasks running at
once) are reported beside it. Run alone: ``python benchmarks/bench_14_sweep.py [--quick]``.
"""

from __future__ import annotations

import shutil
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from suite import benchmark, record

TASKS = 64


def _spec(n_steps: int, members: int, tag: float) -> Any:
    from isoflow.sweep import read_spec

    return read_spec(
        {
            "model": "rigid-body",
            "params": {"n": 10},
            "dt": 0.05,
            "n_steps": n_steps,
            "save_every": n_steps,
            "perturb": tag,
            "members_per_task": members,
            "grid": {"seed": {"start": 0, "stop": TASKS * members}},
        }
    )


def _timed_sweep(client: Any, spec: Any, root: Path, name: str) -> tuple[float, float]:
    """Wall time of the sweep and the sum of its tasks' own times (in the workers)."""
    import isoflow as iso
    from isoflow.sweep.files import read_summary

    out = root / name
    t = time.perf_counter()
    res = iso.sweep.run(spec, out, client=client, progress=False)
    wall = time.perf_counter() - t
    assert res.success and len(res.computed) == TASKS, res
    entries = [{"id": t.id, "members": [m.index for m in t.members]} for t in spec.tasks]
    inside = sum(read_summary(out, e)["task_seconds"] for e in entries)
    shutil.rmtree(out)
    return wall, inside


def _spin(n: int) -> float:
    """A CPU-bound loop (pure Python); its own wall time."""
    t = time.perf_counter()
    x = 0
    for i in range(n):
        x += i
    return time.perf_counter() - t


def _machine_parallelism(n: int = 10_000_000) -> float:
    """What 2 processes give on this machine now: the work of two ``_spin`` loops in one
    process's time over their time side by side in two processes (2 on two free cores)."""
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(2) as pool:
        list(pool.map(_spin, [1000, 1000]))  # start both processes
        one = pool.submit(_spin, n).result()
        t = time.perf_counter()
        list(pool.map(_spin, [n, n]))
        both = time.perf_counter() - t
    return 2 * one / both


def _load() -> float:
    """The 1-minute load average (other work on the machine), NaN where unknown."""
    import os

    try:
        return float(os.getloadavg()[0])
    except OSError:  # pragma: no cover
        return float("nan")


def _cluster(workers: int) -> tuple[Any, Any]:
    from distributed import Client, LocalCluster

    from isoflow.sweep.submit import WORKER_ENV

    cluster = LocalCluster(
        n_workers=workers,
        threads_per_worker=1,
        processes=True,
        dashboard_address=None,
        env=dict(WORKER_ENV),
        silence_logs=50,
    )
    return cluster, Client(cluster)


@benchmark(14, "a sweep of 64 rigid-body ensemble tasks: 2 local workers against 1; cost per task")
def run(quick: bool) -> list[dict[str, Any]]:
    import isoflow as iso

    n_steps = 1500 if quick else 4000
    members = 8
    root = Path(tempfile.mkdtemp(prefix="isoflow-bench14-"))
    walls: dict[int, float] = {}
    busy: dict[int, float] = {}  # the tasks' own times, summed
    overhead = tiny_task = float("nan")
    try:
        for workers in (1, 2):
            cluster, client = _cluster(workers)
            try:
                # warm every worker: imports, numba's cached compiled loop, an HDF5 file
                warm = _spec(20, members, 1e-3)
                iso.sweep.run(warm, root / f"warm{workers}", client=client, progress=False)
                walls[workers], busy[workers] = _timed_sweep(
                    client, _spec(n_steps, members, 1e-3), root, f"run{workers}"
                )
                if workers == 1:
                    wall, inside = _timed_sweep(client, _spec(1, members, 2e-3), root, "tiny")
                    overhead = (wall - inside) / TASKS
                    tiny_task = wall / TASKS
            finally:
                client.close()
                cluster.close()
    finally:
        shutil.rmtree(root, ignore_errors=True)
    parallel = _machine_parallelism()
    speedup = walls[1] / walls[2]
    return [
        record(
            14, f"{TASKS} tasks of {members} so(10) rigid bodies x {n_steps} steps, local workers",
            wall_1_worker_s=walls[1], wall_2_workers_s=walls[2],
            task_s_1_worker=walls[1] / TASKS, task_s_2_workers=busy[2] / TASKS,
            # tasks running at once (sum of task times / wall): 2 when the two workers overlap,
            # whatever the speed-up a machine shared with other load allows
            concurrency_2_workers=busy[2] / walls[2], load_average=_load(),
            machine_speedup_2_processes=parallel,
            metric="speed-up (1 worker / 2 workers)",
            value=speedup, target=">= 1.7", met=speedup >= 1.7,
        ),
        record(
            14, f"scheduling overhead per task, 1 worker ({TASKS} one-step tasks)",
            overhead_ms_per_task=overhead * 1e3, one_step_task_ms_with_files=tiny_task * 1e3,
            metric="overhead per task / 1-s task (%)", value=overhead * 100.0,
            target="<= 5", met=overhead <= 0.05,
        ),
    ]  # fmt: skip


if __name__ == "__main__":
    import run_all

    sys.exit(run_all.main(["--only", "14", *sys.argv[1:]]))
