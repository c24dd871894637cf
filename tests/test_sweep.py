"""Sweeps on dask.distributed (isoflow.sweep): exact members, faults, restarts, lazy results."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import isoflow as iso
from isoflow.sweep import SweepError, member_run, open_sweep, read_spec, status
from isoflow.sweep import results as sweep_results
from isoflow.sweep.files import task_paths

pytest.importorskip("distributed")
pytest.importorskip("xarray")

TESTS = str(Path(__file__).resolve().parent)
SRC = str(Path(iso.__file__).resolve().parents[1])

RIGID = {
    "model": "rigid-body",
    "params": {"n": 6},
    "dt": 0.05,
    "n_steps": 200,
    "save_every": 20,
    "perturb": 1e-3,
    "members_per_task": 3,
    "grid": {"seed": {"start": 0, "stop": 5}},
}


@pytest.fixture(scope="module")
def client():
    """A local cluster of two single-threaded worker processes (3 worker deaths per task)."""
    import dask
    from distributed import Client, LocalCluster

    from isoflow.sweep.run import WORKER_ENV

    old = os.environ.get("PYTHONPATH")
    os.environ["PYTHONPATH"] = os.pathsep.join(p for p in (TESTS, old) if p)
    sys.path.insert(0, TESTS)
    with dask.config.set({"distributed.scheduler.allowed-failures": 3}):
        cluster = LocalCluster(
            n_workers=2,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            env=dict(WORKER_ENV),
        )
    c = Client(cluster)
    try:
        yield c
    finally:
        c.close()
        cluster.close()
        sys.path.remove(TESTS)
        if old is None:
            os.environ.pop("PYTHONPATH", None)
        else:
            os.environ["PYTHONPATH"] = old


def _local(ds, name: str) -> np.ndarray:
    import dask

    with dask.config.set(scheduler="sync"):
        return np.asarray(ds[name].values)


def _assert_members_are_serial_runs(spec, directory) -> None:
    ds = open_sweep(directory)
    y = _local(ds, "y")
    y_final = _local(ds, "y_final")
    for k, i in enumerate(ds.member.values):
        sol = member_run(spec, int(i))
        n = len(sol.ys)  # a failed serial run stops saving; the ensemble keeps the member frozen
        assert np.array_equal(sol.ys, y[k][:n]), f"member {i}"
        assert all(np.array_equal(sol.y_final, row) for row in y[k][n:]), f"member {i}"
        assert np.array_equal(sol.y_final, y_final[k]), f"member {i}"


# ---- the sweep file ----------------------------------------------------------------------------


def test_grid_expansion_rows_times_grid_member_wins() -> None:
    spec = read_spec(
        {
            "model": "brockett",
            "dt": 0.05,
            "n_steps": 4,
            "params": {"n": 3, "scale": 0.5},
            "grid": {"seed": [0, 1], "scale": {"start": 1.0, "stop": 2.0, "num": 3}},
            "members": [{"n": 4}, {"n": 5}],
        }
    )
    rows = [(m.params["n"], m.params["seed"], m.params["scale"]) for m in spec.members]
    assert rows == [(n, s, x) for n in (4, 5) for s in (0, 1) for x in (1.0, 1.5, 2.0)]
    assert [m.index for m in spec.members] == list(range(12))
    ranged = read_spec({"model": "toda", "n_steps": 2, "dt": 0.1,
                        "grid": {"seed": {"start": 1, "stop": 9, "step": 3}}})  # fmt: skip
    assert [m.params["seed"] for m in ranged.members] == [1, 4, 7]
    own = read_spec({"model": "brockett", "n_steps": 2, "dt": 0.1, "grid": {"scale": [1.0]},
                     "members": [{"n": 5, "scale": 9.0}]})  # fmt: skip
    assert own.members[0].params["scale"] == 9.0  # the member's own value wins


def test_grid_duplicate_after_member_override_is_an_error() -> None:
    with pytest.raises(SweepError, match="duplicates member"):
        read_spec(
            {
                "model": "brockett",
                "dt": 0.05,
                "n_steps": 4,
                "grid": {"scale": [1.0, 2.0]},
                "members": [{"n": 5, "scale": 9.0}],
            }
        )


def test_grouping_by_parameters_without_initial_data() -> None:
    spec = read_spec(
        {
            "model": "brockett",
            "dt": 0.05,
            "n_steps": 4,
            "members_per_task": 2,
            "grid": {"seed": [0, 1, 2]},
            "members": [{"n": 3}, {"n": 4}, {"n": 3, "scale": 2.0}],
        }
    )
    groups = [[m.index for m in t.members] for t in spec.tasks]
    # n = 3 (with either scale: an initial-data parameter) in table order, split by 2; then n = 4
    assert groups == [[0, 1], [2, 6], [7, 8], [3, 4], [5]]
    assert len({t.id for t in spec.tasks}) == len(spec.tasks)


def test_task_names_are_stable_across_processes_and_key_order() -> None:
    spec = read_spec(RIGID)
    reordered = dict(reversed(list(RIGID.items())))
    assert [t.id for t in read_spec(reordered).tasks] == [t.id for t in spec.tasks]
    code = (
        "import json, sys\nfrom isoflow.sweep import read_spec\n"
        "print(json.dumps([t.id for t in read_spec(json.loads(sys.argv[1])).tasks]))"
    )
    for seed in ("0", "12345"):
        out = subprocess.run(
            [sys.executable, "-c", code, json.dumps(reordered)],
            capture_output=True, text=True, check=True, timeout=120,
            env=os.environ | {"PYTHONHASHSEED": seed},
        )  # fmt: skip
        assert json.loads(out.stdout) == [t.id for t in spec.tasks]
    other = read_spec(RIGID | {"perturb": 2e-3})
    assert not {t.id for t in other.tasks} & {t.id for t in spec.tasks}
    assert all(len(t.id) == 20 for t in spec.tasks)


BASE = {"model": "rigid-body", "dt": 0.1, "n_steps": 10, "members": [{"n": 4}]}


@pytest.mark.parametrize(
    ("change", "pattern"),
    [
        ({"colour": 1}, r"unknown key\(s\) colour"),
        ({"params": {"m": 3}}, "has no parameter 'm'"),
        ({"members": [{"n": "ten"}]}, "member 0: rigid-body n must be an integer"),
        ({"members": []}, "the sweep has no members"),
        ({"members": [{}]}, r"members\[0\] is an empty table"),
        ({"members": [{"n": 4}, {"n": 4}]}, "member 1 duplicates member 0"),
        ({"members": [{"n": 4, "seed": 1}]}, "seed without perturb"),
        ({"members": [{"n": 4}, {"n": 5, "dt": 0.05, "n_steps": 10}]}, "time grid .* differs"),
        ({"grid": {"n": {"start": 3.5, "stop": 6}}}, "range of integers"),
        ({"grid": {"n": []}}, r"grid.n is empty"),
        ({"n_steps": None}, "exactly two of t1, dt and n_steps"),
        ({"method": "isomq"}, "unknown method 'isomq'"),
        ({"perturb": -1.0}, "perturb must be a positive number"),
        ({"members_per_task": 0}, "members_per_task must be an integer >= 1"),
    ],
)
def test_bad_sweeps_are_one_line_typed_errors(change: dict, pattern: str) -> None:
    table = {k: v for k, v in (BASE | change).items() if v is not None}
    with pytest.raises(SweepError, match=pattern) as info:
        read_spec(table)
    assert "\n" not in str(info.value)
    assert isinstance(info.value, iso.IsoflowError) and isinstance(info.value, ValueError)


@pytest.mark.parametrize(
    "text",
    ['model = "rigid-body"\ndt = 0.1\nn_steps = 10\n[[members]]\nn = 4\nseed = 2\n',
     'model = "rigid-body"\ndt = 0.1\n[[members]\n'],
)  # fmt: skip
def test_cli_bad_sweep_file_exits_1_with_one_line(tmp_path: Path, text: str) -> None:
    f = tmp_path / "bad.toml"
    f.write_text(text)
    out = subprocess.run(
        [sys.executable, "-m", "isoflow.cli", "sweep", str(f), "--out", str(tmp_path / "o")],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert out.returncode == 1
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("isoflow: error: "), out.stderr
    assert not (tmp_path / "o").exists()


def test_iso_sweep_is_callable_after_importing_a_submodule() -> None:
    code = (
        "import isoflow as iso\nimport isoflow.sweep.spec\nimport isoflow.sweep.task\n"
        "assert callable(iso.sweep) and iso.sweep.read_spec is isoflow.sweep.spec.read_spec\n"
        "try:\n    iso.sweep({'model': 'rigid-body'}, 'x')\n"
        "except iso.sweep.SweepError as e:\n    print(e)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=120)  # fmt: skip
    assert "the sweep has no members" in out.stdout


# ---- running -----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "table",
    [
        RIGID,
        {"model": "brockett", "params": {"n": 4}, "dt": 0.05, "n_steps": 60, "save_every": 7,
         "grid": {"seed": [0, 1, 2], "scale": [0.5, 1.0]}, "members_per_task": 4},
        {"model": "toda", "params": {"n": 5}, "method": "isomp", "solver": "newton", "dt": 0.1,
         "t1": 5.0, "save_every": 10, "grid": {"seed": {"start": 0, "stop": 4}}},
        {"model": "mhd-sphere", "params": {"N": 5, "lmax": 3}, "dt": 0.05, "n_steps": 40,
         "save_every": 10, "grid": {"seed": [0, 1, 2]}, "members_per_task": 2},
        {"model": "heavy-top", "params": {"top": "kovalevskaya"}, "dt": 0.01, "n_steps": 100,
         "save_every": 25, "perturb": 1e-2, "grid": {"seed": {"start": 0, "stop": 3}}},
    ],
    ids=["perturbed-rigid-body", "brockett", "toda", "mhd-sphere", "perturbed-heavy-top"],
)  # fmt: skip
def test_every_member_equals_a_serial_solve(client, tmp_path: Path, table: dict) -> None:
    spec = read_spec(table)
    res = iso.sweep(spec, tmp_path / "s", client=client, progress=False)
    assert res.success and sorted(res.computed) == sorted(t.id for t in spec.tasks)
    _assert_members_are_serial_runs(spec, tmp_path / "s")
    ds = open_sweep(tmp_path / "s")
    assert set(ds.status.values) == {"finished"}
    assert sorted(ds.member.values) == list(range(len(spec.members)))
    again = iso.sweep(spec, tmp_path / "s", client=client, progress=False)
    assert again.computed == [] and len(again.skipped) == len(spec.tasks)


def test_open_sweep_is_lazy_and_reads_each_file_once(
    client, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import dask

    spec = read_spec(RIGID)
    iso.sweep(spec, tmp_path, client=client, progress=False)
    calls: list[str] = []
    real = sweep_results.read_task

    def counting(path):
        calls.append(Path(path).name)
        return real(path)

    monkeypatch.setattr(sweep_results, "read_task", counting)
    ds = open_sweep(tmp_path)
    assert calls == []
    assert ds.y.data.numblocks[0] == len(spec.tasks)
    with dask.config.set(scheduler="sync"):
        loaded = ds.compute()
    assert sorted(calls) == sorted(f"{t.id}.h5" for t in spec.tasks)
    assert {"y", "y_final", "casimirs", "hamiltonian"} <= set(loaded.data_vars)
    assert np.array_equal(loaded.y_final.values, loaded.y.values[:, -1])
    sel = open_sweep(tmp_path, where={"seed": 4})
    with dask.config.set(scheduler="sync"):
        assert sel.y.shape[0] == 1 and np.array_equal(sel.y.values[0], loaded.y.sel(member=4))
        # the files layer's entry to the same reader
        assert iso.io.open_sweep(tmp_path, where={"seed": 4}).identical(sel)


def test_failing_member_and_raising_task_are_reported_others_finish(client, tmp_path: Path) -> None:
    table = {
        "model": "brockett",
        "params": {"n": 4},
        "dt": 0.05,
        "n_steps": 40,
        "members": [{"seed": 0}, {"seed": 1, "scale": 1e6}, {"seed": 2}],
    }
    spec = read_spec(table)
    res = iso.sweep(spec, tmp_path / "fail", client=client, progress=False)
    assert res.failed_members == [1] and not res.errors
    ds = open_sweep(tmp_path / "fail")
    st = dict(zip(ds.member.values.tolist(), ds.status.values.tolist(), strict=True))
    assert st == {0: "finished", 1: "failed", 2: "finished"}
    assert int(ds.failed_step.sel(member=1)) == 0 and ds.message.sel(member=1) == "diverged"
    _assert_members_are_serial_runs(spec, tmp_path / "fail")
    info = status(tmp_path / "fail")
    assert info["failed_members"] == {"1": {"step": 0, "message": "diverged"}}

    # a task that raises (so(0) is not a space), next to one that runs
    toy = {"model": "user_models:toy_rigid_body", "dt": 0.1, "n_steps": 10,
           "members": [{"n": 0}, {"n": 3}]}  # fmt: skip
    spec = read_spec(toy)
    res = iso.sweep(spec, tmp_path / "raise", client=client, progress=False)
    bad, good = spec.tasks
    assert list(res.errors) == [bad.id] and "ParameterError" in res.errors[bad.id]
    assert res.computed == [good.id]
    ds = open_sweep(tmp_path / "raise")
    assert list(ds.status.values) == ["error", "finished"]
    assert np.isnan(_local(ds, "y")[0]).all() and np.isfinite(_local(ds, "y")[1]).all()
    assert "ParameterError" in task_paths(tmp_path / "raise", bad.id).log.read_text()
    assert status(tmp_path / "raise")["errors"] == {bad.id: res.errors[bad.id]}
    out = subprocess.run([sys.executable, "-m", "isoflow.cli", "info", str(tmp_path / "fail")],
                         capture_output=True, text=True, check=True, timeout=120)  # fmt: skip
    assert re.search(r"members +3 in 1 task\n", out.stdout) and "member 1" in out.stdout
    assert "failed at step 0: diverged" in out.stdout
    out = subprocess.run(
        [sys.executable, "-m", "isoflow.cli", "info", "--json", str(tmp_path / "raise")],
        capture_output=True, text=True, check=True, timeout=120,
    )  # fmt: skip
    assert json.loads(out.stdout)["errors"] == res.errors


def test_rerun_redoes_only_deleted_summaries_and_files(client, tmp_path: Path) -> None:
    spec = read_spec(RIGID)
    iso.sweep(spec, tmp_path, client=client, progress=False)
    a, b = spec.tasks[0].id, spec.tasks[1].id
    task_paths(tmp_path, a).json.unlink()
    task_paths(tmp_path, b).json.unlink()
    task_paths(tmp_path, b).h5.unlink()
    res = iso.sweep(spec, tmp_path, client=client, progress=False)
    assert sorted(res.computed) == sorted([a, b]) and res.skipped == []
    assert "resumed" in task_paths(tmp_path, a).log.read_text()
    _assert_members_are_serial_runs(spec, tmp_path)


# ---- killing -----------------------------------------------------------------------------------

#: Tasks long enough (about a second) to be killed in the middle, checkpointed every row.
LONG = {
    "model": "rigid-body",
    "params": {"n": 10},
    "dt": 0.05,
    "n_steps": 24000,
    "save_every": 2400,
    "perturb": 1e-3,
    "members_per_task": 4,
    "chunk_rows": 1,
    "flush_seconds": 0.05,
    "grid": {"seed": {"start": 0, "stop": 8}},
}


def _running_task(directory: Path, spec, timeout: float = 60.0) -> tuple[str, int]:
    """A running task checkpointed past step 0 and less than half done, and its worker's pid.

    Less than half done, so that it is still running when killed a moment later (the workers
    of a killed client notice within a fraction of a second); past step 0, so that it resumes.
    """
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        for t in spec.tasks:
            p = task_paths(directory, t.id)
            if not (p.h5.exists() and p.lock.exists()) or p.json.exists():
                continue
            try:
                step = iso.io.info(p.h5)["step"]
                text = p.lock.read_text().strip()
            except (iso.IsoflowError, OSError):  # being created or replaced right now
                continue
            if text and step and 0 < step < spec.run["n_steps"] // 2:
                return t.id, int(text)
        time.sleep(0.01)
    raise AssertionError("no task was seen running")


def _read_log(directory: Path, task_id: str) -> str:
    path = task_paths(directory, task_id).log
    return path.read_text() if path.exists() else ""


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/status").read_text()
    except FileNotFoundError:
        return False
    return "\nState:\tZ" not in state


def _assert_same_results(a: Path, b: Path) -> None:
    import dask

    with dask.config.set(scheduler="sync"):
        da, db = open_sweep(a).sortby("member").compute(), open_sweep(b).sortby("member").compute()
    assert set(da.data_vars) == set(db.data_vars)
    for name in da.data_vars:
        assert np.array_equal(da[name].values, db[name].values), name


def test_worker_killed_mid_task_is_retried_and_resumed(client, tmp_path: Path) -> None:
    spec = read_spec(LONG)
    out: dict = {}
    th = threading.Thread(
        target=lambda: out.update(r=iso.sweep(spec, tmp_path / "k", client=client, progress=False))
    )
    th.start()
    tid, pid = _running_task(tmp_path / "k", spec)
    os.kill(pid, signal.SIGKILL)
    th.join(120)
    res = out["r"]
    assert res.success and len(res.computed) == len(spec.tasks)
    log = task_paths(tmp_path / "k", tid).log.read_text()
    assert log.count("start:") == 1 and "resumed" in log, log
    iso.sweep(spec, tmp_path / "ref", client=client, progress=False)
    _assert_same_results(tmp_path / "k", tmp_path / "ref")


def test_client_killed_and_restarted_finishes_like_an_uninterrupted_run(
    client, tmp_path: Path
) -> None:
    f = tmp_path / "long.toml"
    lines = [f"{k} = {json.dumps(v)}" for k, v in LONG.items() if not isinstance(v, dict)]
    # four tasks on two workers: when the first is done, another one is still running
    f.write_text("\n".join(lines) + "\n[params]\nn = 10\n[grid]\nseed = {start = 0, stop = 16}\n")
    spec = read_spec(f)
    d = tmp_path / "d"
    cmd = [sys.executable, "-m", "isoflow.cli", "sweep", str(f), "--out", str(d),
           "--workers", "2", "--quiet"]  # fmt: skip
    env = os.environ | {"OPENBLAS_NUM_THREADS": "1"}
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        end = time.monotonic() + 90
        while not any(task_paths(d, t.id).json.exists() for t in spec.tasks):
            assert time.monotonic() < end and proc.poll() is None, proc.stderr
            time.sleep(0.01)
        _tid, _pid = _running_task(d, spec)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(30)
    locks = [task_paths(d, t.id).lock for t in spec.tasks]  # not the result files' own locks
    workers = {int(p.read_text()) for p in locks if p.exists() and p.read_text().strip()}
    end = time.monotonic() + 15
    while any(_alive(p) for p in workers) and time.monotonic() < end:
        time.sleep(0.05)
    assert not any(_alive(p) for p in workers), "workers outlived the client"
    done = {
        t.id: task_paths(d, t.id).json.read_text()
        for t in spec.tasks
        if task_paths(d, t.id).json.exists()
    }
    assert 0 < len(done) < len(spec.tasks)
    again = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=180)
    assert again.returncode == 0, again.stderr
    assert f"{len(done)} already done" in again.stdout
    for tid, text in done.items():  # not recomputed
        assert task_paths(d, tid).json.read_text() == text
    logs = {t.id: _read_log(d, t.id) for t in spec.tasks}
    assert any("resumed" in text for text in logs.values()), logs
    iso.sweep(spec, tmp_path / "ref", client=client, progress=False)
    _assert_same_results(d, tmp_path / "ref")
