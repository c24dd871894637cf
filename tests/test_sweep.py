"""Sweeps on dask.distributed (isoflow.sweep): exact members, faults, restarts, lazy results."""

from __future__ import annotations

import errno
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import isoflow as iso
from isoflow.cli import main
from isoflow.sweep import (
    SweepError,
    build_member,
    member_run,
    open_sweep,
    read_spec,
    run_task,
    status,
)
from isoflow.sweep import results as sweep_results
from isoflow.sweep.files import seal, task_paths, write_manifest
from isoflow.sweep.task import task_layouts

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

    from isoflow.sweep.submit import WORKER_ENV

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


def test_initial_data_that_changes_the_model_is_refused() -> None:
    """A parameter listed in ``initial`` groups members into one task, which runs them all with
    the first member's ``B``: one that changes the model is refused (a built-in model's when
    the sweep is read, a user's model's when its task is built), not run silently wrong."""
    from isoflow.sweep import SweepError
    from isoflow.sweep.task import build_task

    with pytest.raises(SweepError, match=r"initial: omega of the built-in model 'euler-sphere' "
                       r"changes the model, not only the initial state"):  # fmt: skip
        read_spec({"model": "euler-sphere", "initial": ["omega"], "dt": 0.01, "n_steps": 2,
                   "params": {"N": 8}, "grid": {"omega": [0.0, 5.0]}})  # fmt: skip
    base = {"model": "user_models:scaled_rigid_body", "dt": 0.05, "n_steps": 2,
            "members_per_task": 4}  # fmt: skip
    spec = read_spec(base | {"initial": ["c"], "grid": {"c": [1.0, 2.0]}})
    assert len(spec.tasks) == 1
    with pytest.raises(SweepError, match=r"members 0 and 1 share a task but c change the model "
                       r"\(B differs"):  # fmt: skip
        build_task(spec, spec.tasks[0])
    fine = read_spec(base | {"initial": ["seed"], "grid": {"seed": [0, 1, 2]}})
    _, Y, _, _ = build_task(fine, fine.tasks[0])
    assert Y.shape == (3, 4, 4) and len(fine.tasks) == 1


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
            capture_output=True, text=True, check=True, timeout=600,
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
        # too many members, counted before a single one is listed
        ({"grid": {k: {"start": 0, "stop": 1000} for k in "abc"}},
         r"the sweep has 1,000,000,000 members \(1 \[\[members\]\] row x 1000 values of a x "
         r"1000 values of b x 1000 values of c\), more than the limit of 100,000: split it"),
        ({"grid": {"n": {"start": 0.0, "stop": 1.0, "num": 10**12}}},
         "1,000,000,000,000 members"),
        ({"grid": {"n": {"start": 0, "stop": 10**18}}}, "1,000,000,000,000,000,000 members"),
        ({"members": [{"n": 4}, {"n": 5}], "grid": {"seed": {"start": 0, "stop": 50_001}}},
         r"100,002 members \(2 \[\[members\]\] rows x 50001 values of seed\)"),
        ({"n_steps": 2**30, "dt": 1e-9}, "would save 1,073,741,825 states"),
    ],
)  # fmt: skip
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
def test_cli_bad_sweep_file_exits_1_with_one_line(
    tmp_path: Path, text: str, capsys: pytest.CaptureFixture[str]
) -> None:
    f = tmp_path / "bad.toml"
    f.write_text(text)
    assert main(["sweep", str(f), "--out", str(tmp_path / "o")]) == 1
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"isoflow: error: {f}: "), lines
    assert not (tmp_path / "o").exists()


def test_iso_sweep_run_is_the_function_after_importing_every_submodule() -> None:
    import isoflow.sweep.spec
    import isoflow.sweep.submit
    import isoflow.sweep.task

    assert iso.sweep.run is isoflow.sweep.submit.run and not callable(iso.sweep)
    assert iso.sweep.read_spec is isoflow.sweep.spec.read_spec
    with pytest.raises(iso.sweep.SweepError, match="the sweep has no members"):
        iso.sweep.run({"model": "rigid-body"}, "x")


def test_a_factory_with_its_own_seed_is_swept_over_it() -> None:
    spec = read_spec({"model": "user_models:toy_rigid_body", "dt": 0.1, "n_steps": 4,
                      "grid": {"seed": [0, 1, 2]}})  # fmt: skip
    assert [m.params["seed"] for m in spec.members] == [0, 1, 2]
    assert [m.seed for m in spec.members] == [None] * 3  # no perturbation: none to seed
    states = [build_member(spec, m)[1] for m in spec.members]
    assert not np.array_equal(states[0], states[1]) and not np.array_equal(states[1], states[2])
    assert len(spec.tasks) == 3  # a seed of a factory may change B: not initial data by default
    own = read_spec({"model": "user_models:toy_rigid_body", "dt": 0.1, "n_steps": 4,
                     "initial": ["seed"], "grid": {"seed": [0, 1, 2]}})  # fmt: skip
    assert [len(t.members) for t in own.tasks] == [3]


def test_without_the_extra_a_sweep_says_how_to_install_it(tmp_path: Path) -> None:
    f = tmp_path / "s.toml"
    f.write_text('model = "rigid-body"\ndt = 0.1\nn_steps = 4\n[[members]]\nn = 3\n')
    code = f"""
import contextlib, io, json, sys
for name in ("dask", "distributed", "xarray"):
    sys.modules[name] = None  # not installed
import isoflow as iso
from isoflow.cli import main
out = {{}}
for what, call in (("sweep", lambda: iso.sweep.run({str(f)!r}, {str(tmp_path / "o")!r})),
                   ("open", lambda: iso.sweep.open_sweep({str(tmp_path)!r}))):
    try:
        call()
    except iso.sweep.MissingExtraError as exc:
        out[what] = [str(exc), isinstance(exc, ImportError), isinstance(exc, iso.IsoflowError)]
err = io.StringIO()
with contextlib.redirect_stderr(err):
    out["cli"] = [main(["sweep", {str(f)!r}, "--out", {str(tmp_path / "o")!r}]), err.getvalue()]
print(json.dumps(out))
"""
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=600, check=True)  # fmt: skip
    out = json.loads(run.stdout)
    hint = "pip install 'isoflow[sweep]'"
    for what in ("sweep", "open"):
        text, is_import_error, is_ours = out[what]
        assert text.endswith(hint) and "dask does not import" in text and "\n" not in text
        assert is_import_error and is_ours
    status_, err = out["cli"]
    assert status_ == 1 and err.count("\n") == 1 and err.startswith("isoflow: error: sweeps need")
    assert err.strip().endswith(hint)
    assert not (tmp_path / "o").exists()


def test_more_workers_than_cores_are_capped_with_a_warning(
    capsys: pytest.CaptureFixture[str],
) -> None:
    from isoflow.cli._common import warnings_as_lines
    from isoflow.sweep.submit import _capped_workers
    from isoflow.threads import available_cores

    cores = available_cores()
    with pytest.warns(RuntimeWarning, match=f"workers = 999 is more than the {cores} cores"):
        assert _capped_workers(999) == cores
    assert _capped_workers(None) == cores and _capped_workers(1) == 1
    with warnings_as_lines():  # as isoflow sweep shows it
        assert _capped_workers(999) == cores
    err = capsys.readouterr().err
    assert err.startswith(f"isoflow: warning: workers = 999 is more than the {cores} cores")
    assert err.count("\n") == 1


# ---- sweep directories (tasks run in this process, no cluster) ---------------------------------

#: Three one-member tasks of a small perturbed rigid body.
SMALL = {
    "model": "rigid-body",
    "params": {"n": 4},
    "dt": 0.05,
    "n_steps": 20,
    "save_every": 5,
    "perturb": 1e-3,
    "members_per_task": 1,
    "grid": {"seed": {"start": 0, "stop": 3}},
}


def _prepared(spec, directory: Path) -> Path:
    """A sweep directory as a sweep writes it before any task runs."""
    write_manifest(directory, spec, task_layouts(spec))
    return directory


@pytest.fixture(scope="module")
def finished(tmp_path_factory: pytest.TempPathFactory):
    """``(spec, directory)`` of SMALL with every task run here (no cluster)."""
    spec = read_spec(SMALL)
    d = _prepared(spec, tmp_path_factory.mktemp("finished"))
    for t in spec.tasks:
        run_task(spec, t.id, d)
    return spec, d


@pytest.fixture
def copy(finished, tmp_path: Path):
    """A copy of the finished sweep directory to damage."""
    spec, d = finished
    shutil.copytree(d, tmp_path / "s")
    return spec, tmp_path / "s"


def _values(directory: Path) -> dict[str, np.ndarray]:
    import dask

    with dask.config.set(scheduler="sync"):
        ds = open_sweep(directory).sortby("member").compute()
    return {name: ds[name].values for name in ds.data_vars}


def _edit(fn):
    def edit(text: str) -> str:
        data = json.loads(text)
        fn(data)
        return json.dumps(data)

    return edit


def _resealed(fn):
    """An edit after which the summary's checksum is recomputed (a deliberate forgery)."""
    return _edit(lambda data: (fn(data), data.update(checksum=seal(data)["checksum"])))


MANIFEST_CASES = {
    "empty": (lambda t: "", "empty$"),
    "truncated": (lambda t: t[: len(t) // 2], r"not valid JSON \(truncated\?\)$"),
    "{}": (lambda t: "{}", "not an isoflow sweep manifest$"),
    "a list": (lambda t: "[1]", "a JSON list, not a table$"),
    "old version": (_edit(lambda d: d.update(format_version=1)), "format version 1, not 2"),
    "no members": (_edit(lambda d: d.pop("members")), "'members' is not a list$"),
    "no tasks": (_edit(lambda d: d.pop("tasks")), "'tasks' is not a non-empty list$"),
    "no run": (_edit(lambda d: d.pop("run")), "'run' is not a table$"),
    "no layouts": (_edit(lambda d: d.pop("layouts")), "no 'layouts'$"),
    "n_steps a string": (_edit(lambda d: d["run"].update(n_steps="20")), "'n_steps' is not an"),
    "saves 1e18 states": (
        _edit(lambda d: d["run"].update(n_steps=10**18, save_every=1)),
        "'run' saves more than 16777216 states",
    ),
    "member out of range": (
        _edit(lambda d: d["tasks"][0].update(members=[7])),
        "lists members that the manifest does not have",
    ),
    "member twice": (
        _edit(lambda d: d["tasks"][1].update(members=[0])),
        "repeats members of another task",
    ),
    "a member in no task": (_edit(lambda d: d["tasks"].pop()), "some members belong to no task"),
    "task id a path": (
        _edit(lambda d: d["tasks"][0].update(id="../../x")),
        "task 0 has id '../../x'",
    ),
    "member without params": (
        _edit(lambda d: d["members"][0].pop("params")),
        "member 0 has no 'params' table",
    ),
    "member index": (_edit(lambda d: d["members"][1].update(index=0)), "member 1 has index 0"),
    "huge layout": (
        _edit(lambda d: d["layouts"][0].update(state_shape=[10**9, 10**9])),
        r"state_shape: shape \(1000000000, 1000000000\) is too large",
    ),
    "layout dtype": (
        _edit(lambda d: d["layouts"][0].update(state_dtype="object")),
        "dtype object is not numeric",
    ),
    "layout index": (_edit(lambda d: d["tasks"][0].update(layout=3)), "has layout 3"),
    "errors a list": (_edit(lambda d: d.update(errors=[])), "'errors' is not a table"),
    "perturb": (_edit(lambda d: d.update(perturb="big")), "'perturb' is not > 0"),
}


@pytest.mark.parametrize("case", list(MANIFEST_CASES))
def test_a_malformed_manifest_is_one_line_naming_it(
    copy, case: str, capsys: pytest.CaptureFixture[str]
) -> None:
    _spec, d = copy
    edit, pattern = MANIFEST_CASES[case]
    path = d / "sweep.json"
    path.write_text(edit(path.read_text()))
    for read in (status, open_sweep):
        with pytest.raises(SweepError) as info:
            read(d)
        assert str(info.value).startswith(f"{path}: ") and "\n" not in str(info.value)
        assert re.search(pattern, str(info.value)), str(info.value)
    assert main(["info", str(d)]) == 1
    assert capsys.readouterr().err == f"isoflow: error: {info.value}\n"


SUMMARY_CASES = {
    "empty": (lambda t: "", "empty"),
    "truncated": (lambda t: t[: len(t) // 2], r"not valid JSON \(truncated\?\)"),
    "{}": (lambda t: "{}", "its checksum does not match"),
    "a list": (lambda t: "[]", "a JSON list, not a table"),
    "edited": (_edit(lambda d: d.update(status=["failed"])), "its checksum does not match"),
    "no checksum": (_edit(lambda d: d.pop("checksum")), "its checksum does not match"),
    "another task's": (_resealed(lambda d: d.update(id="0" * 20)), "the summary of task '0000"),
    "other members": (_resealed(lambda d: d.update(members=[2])), "members are not the task's"),
    "short status": (_resealed(lambda d: d.update(status=[])), "'status' is not a status list"),
    "no drifts": (_resealed(lambda d: d.pop("drifts")), "no 'drifts'"),
    "drift text": (
        _resealed(lambda d: d["drifts"].update(casimir_drift=["x"])),
        "drift 'casimir_drift' is not a list of 1 numbers",
    ),
    "huge state": (_resealed(lambda d: d.update(state_shape=[2**40])), "is too large"),
    "no file hash": (_resealed(lambda d: d.pop("file_sha256")), "no 'file_sha256'"),
}


@pytest.mark.parametrize("case", list(SUMMARY_CASES))
def test_a_malformed_summary_marks_its_task_damaged_and_is_redone(
    finished, copy, case: str, capsys: pytest.CaptureFixture[str]
) -> None:
    spec, d = copy
    edit, pattern = SUMMARY_CASES[case]
    task = spec.tasks[0]
    path = task_paths(d, task.id).json
    path.write_text(edit(path.read_text()))
    damaged = status(d)["damaged"]
    assert list(damaged) == [task.id] and damaged[task.id].startswith(f"{path}: ")
    assert re.search(pattern, damaged[task.id]) and "run the sweep again" in damaged[task.id]
    ds = open_sweep(d)
    assert ds.status.sel(member=0) == "pending" and ds.message.sel(member=0) == damaged[task.id]
    assert main(["info", str(d)]) == 0
    assert re.search(
        rf"  task {task.id} +damaged: {re.escape(str(path))}: ", capsys.readouterr().out
    )
    run_task(spec, task.id, d)  # what the sweep's worker does: it runs the task again
    assert status(d, verify=True)["done"] == len(spec.tasks)
    assert all(np.array_equal(a, b) for a, b in zip(
        _values(d).values(), _values(finished[1]).values(), strict=True))  # fmt: skip


@pytest.mark.parametrize("damage", ["deleted", "truncated", "scrambled", "another task's"])
def test_a_damaged_result_file_marks_its_task_damaged_and_is_redone(copy, damage: str) -> None:
    spec, d = copy
    task, other = spec.tasks[0], spec.tasks[1]
    h5 = task_paths(d, task.id).h5
    if damage == "deleted":
        h5.unlink()
    elif damage == "truncated":
        _truncate(h5)
    elif damage == "scrambled":
        _scramble(h5)
    else:
        h5.write_bytes(task_paths(d, other.id).h5.read_bytes())
    shallow, deep = status(d)["damaged"], status(d, verify=True)["damaged"]
    message = deep[task.id]
    assert list(deep) == [task.id] and message.startswith(f"{task_paths(d, task.id).json}: ")
    expected = {"deleted": f"its result file {h5.name} is missing",
                "truncated": f"its result file {h5.name} changed size"}.get(
                    damage, f"its result file {h5.name} changed")  # fmt: skip
    assert f": {expected};" in message
    if damage in ("deleted", "truncated"):
        assert shallow == deep  # a size or a missing file is seen without reading the file
    run_task(spec, task.id, d)
    assert status(d, verify=True)["damaged"] == {}
    _assert_members_are_serial_runs(spec, d)


def test_a_partial_task_of_another_task_s_file_starts_again(copy) -> None:
    spec, d = copy
    task, other = spec.tasks[0], spec.tasks[1]
    p = task_paths(d, task.id)
    p.json.unlink()
    p.h5.write_bytes(task_paths(d, other.id).h5.read_bytes())
    run_task(spec, task.id, d)
    assert "is not this task's result file; starting again" in p.log.read_text()
    assert iso.io.info(p.h5)["config"]["sweep"] == {"task": task.id, "digest": task.digest}
    _assert_members_are_serial_runs(spec, d)


def test_before_any_task_finished_results_are_nan_of_the_right_shape(finished, tmp_path) -> None:
    spec, done = finished
    d = _prepared(spec, tmp_path)
    empty, full = open_sweep(d), open_sweep(done)
    drifts = {k for k in full.data_vars if k.endswith("_drift") or k == "max_distance"}
    assert drifts and set(empty.data_vars) == set(full.data_vars) - drifts  # drifts: when done
    for name in ("y", "y_final", "casimirs", "hamiltonian"):
        assert empty[name].shape == full[name].shape and empty[name].dtype == full[name].dtype
        assert np.isnan(_local(empty, name)).all()
    assert set(empty.status.values) == {"pending"}


def test_members_of_different_shapes_are_opened_one_shape_at_a_time(tmp_path: Path) -> None:
    spec = read_spec({"model": "rigid-body", "dt": 0.1, "n_steps": 4,
                      "members": [{"n": 3}, {"n": 4}]})  # fmt: skip
    d = _prepared(spec, tmp_path)
    with pytest.raises(SweepError, match=r"different shapes \(\(3, 3\) \(.*\); \(4, 4\) .*where="):
        open_sweep(d)
    run_task(spec, spec.tasks[1].id, d)
    assert open_sweep(d, where={"n": 3}).y.shape == (1, 5, 3, 3)
    four = open_sweep(d, where={"n": 4})
    assert np.array_equal(_local(four, "y")[0], member_run(spec, 1).ys)
    with pytest.raises(SweepError, match=r"where: the sweep's members have no parameter zz \("):
        open_sweep(d, where={"zz": 7})  # selected no member, silently
    with pytest.raises(SweepError, match=r"member_run needs a SweepSpec .*got str"):
        member_run(str(d), 0)  # type: ignore[arg-type]
    with pytest.raises(SweepError, match=r"member_run: no member 2 \(the sweep has 2\)"):
        member_run(spec, 2)
    with pytest.raises(SweepError, match="a sweep takes at least one step, got n_steps = 0"):
        read_spec({"model": "rigid-body", "dt": 0.1, "n_steps": 0, "members": [{"n": 3}]})


def test_a_task_whose_members_all_failed_is_frozen_at_its_last_good_state(tmp_path) -> None:
    spec = read_spec({"model": "brockett", "params": {"n": 4}, "dt": 0.05, "n_steps": 40,
                      "save_every": 4, "members": [{"seed": 1, "scale": 1e6}]})  # fmt: skip
    d = _prepared(spec, tmp_path)
    summary = run_task(spec, spec.tasks[0].id, d)
    assert summary["status"] == ["failed"]
    ds = open_sweep(d)
    assert ds.y.shape == (1, 11, 4, 4)
    _assert_members_are_serial_runs(spec, d)


def test_a_member_whose_compiled_b_raises_fails_alone(tmp_path) -> None:
    """One task of three members; the middle one's ``CompiledB`` raises in the middle of the
    run: it alone is ``failed`` (not the task an ``error``), the others finish."""
    spec = read_spec({"model": "user_models:raising_toy", "dt": 0.05, "n_steps": 40,
                      "save_every": 4, "initial": ["scale"],
                      "members": [{"scale": 0.1}, {"scale": 0.8}, {"scale": 0.2}]})  # fmt: skip
    (task,) = spec.tasks
    d = _prepared(spec, tmp_path)
    summary = run_task(spec, task.id, d)
    assert summary["status"] == ["finished", "failed", "finished"]
    assert summary["failed_step"][0] == summary["failed_step"][2] == -1
    assert 0 < summary["failed_step"][1] < 40
    ds = open_sweep(d)
    assert ds.message.sel(member=1) == "B raised: ValueError: entry too large"
    assert status(d)["errors"] == {}
    _assert_members_are_serial_runs(spec, d)


def test_a_sweep_task_file_points_at_its_sweep(finished, capsys) -> None:
    spec, d = finished
    h5 = task_paths(d, spec.tasks[0].id).h5
    assert main(["info", str(h5)]) == 0
    out = capsys.readouterr().out
    assert f"task {spec.tasks[0].id} of the sweep in {d}: run the sweep again to resume it" in out
    assert "(not built in" not in out and "resume with isoflow run --resume" not in out
    assert main(["run", "--resume", str(h5)]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"isoflow: error: {h5} is task {spec.tasks[0].id} of the sweep in")
    assert err.count("\n") == 1


def test_a_full_disk_at_the_start_names_the_manifest_and_leaves_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    f = tmp_path / "s.toml"
    f.write_text('model = "rigid-body"\ndt = 0.1\nn_steps = 4\n[[members]]\nn = 3\n')
    d = tmp_path / "out"

    def full(fd: int) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "fsync", full)
    assert main(["sweep", str(f), "--out", str(d)]) == 1
    assert capsys.readouterr().err == (
        f"isoflow: error: {d / 'sweep.json'}: cannot write: No space left on device\n"
    )
    assert sorted(p.name for p in d.rglob("*")) == ["tasks"]  # no temporary file left


@pytest.mark.parametrize(
    ("reply", "pattern"),
    [
        (None, r"no dask scheduler answered at tcp://127\.0\.0\.1:\d+ within 0\.5 s"),
        (b"HTTP/1.1 502 Bad Gateway\r\n\r\n" * 4,
         r"tcp://127\.0\.0\.1:\d+ does not answer as a dask scheduler \(MemoryError"),
    ],
    ids=["silent", "foreign protocol"],
)  # fmt: skip
def test_a_scheduler_address_that_is_not_a_scheduler_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], reply: bytes | None, pattern: str
) -> None:
    """A server that accepts the connection and never speaks dask (as an HTTP server waits for
    a request), or answers in another protocol (as a proxy)."""
    import socketserver

    class Peer(socketserver.BaseRequestHandler):
        def handle(self) -> None:
            if reply is not None:
                self.request.sendall(reply)
            while self.request.recv(1 << 16):  # keep the connection until the client gives up
                pass

    f = tmp_path / "s.toml"
    f.write_text('model = "rigid-body"\ndt = 0.1\nn_steps = 4\n[[members]]\nn = 3\n')
    with socketserver.ThreadingTCPServer(("127.0.0.1", 0), Peer) as server:
        server.daemon_threads = True
        threading.Thread(target=server.serve_forever, daemon=True).start()
        address = f"tcp://127.0.0.1:{server.server_address[1]}"
        args = ["--out", str(tmp_path / "o"), "--scheduler", address, "--connect-timeout", "0.5",
                "--quiet"]  # fmt: skip
        assert main(["sweep", str(f), *args]) == 1
        server.shutdown()
    err = capsys.readouterr().err
    assert err.startswith("isoflow: error: ") and err.count("\n") == 1
    assert re.search(pattern, err), err


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
    res = iso.sweep.run(spec, tmp_path / "s", client=client, progress=False)
    assert res.success and sorted(res.computed) == sorted(t.id for t in spec.tasks)
    _assert_members_are_serial_runs(spec, tmp_path / "s")
    ds = open_sweep(tmp_path / "s")
    assert set(ds.status.values) == {"finished"}
    assert sorted(ds.member.values) == list(range(len(spec.members)))
    again = iso.sweep.run(spec, tmp_path / "s", client=client, progress=False)
    assert again.computed == [] and len(again.skipped) == len(spec.tasks)


def test_open_sweep_is_lazy_and_reads_each_file_once(
    client, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import dask

    spec = read_spec(RIGID)
    iso.sweep.run(spec, tmp_path, client=client, progress=False)
    calls: list[str] = []
    real = sweep_results.read_task

    def counting(path, *args):
        calls.append(Path(path).name)
        return real(path, *args)

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
    assert not hasattr(iso.io, "open_sweep")  # one name for the reader: iso.sweep.open_sweep


def test_failing_member_and_raising_task_are_reported_others_finish(
    client, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    f = tmp_path / "fail.toml"
    f.write_text(
        'model = "brockett"\ndt = 0.05\nn_steps = 40\n[params]\nn = 4\n[[members]]\nseed = 0\n'
        "[[members]]\nseed = 1\nscale = 1e6\n[[members]]\nseed = 2\n"
    )
    spec = read_spec(f)
    # the command line on the running scheduler: a failed member makes the exit status 1
    args = ["--out", str(tmp_path / "fail"), "--scheduler", client.scheduler.address, "--quiet"]
    assert main(["sweep", str(f), *args]) == 1
    out = capsys.readouterr().out
    assert "1 member(s) failed" in out and "failed members: 1 (isoflow info" in out
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
    res = iso.sweep.run(spec, tmp_path / "raise", client=client, progress=False)
    bad, good = spec.tasks
    assert list(res.errors) == [bad.id] and "ParameterError" in res.errors[bad.id]
    assert res.computed == [good.id]
    ds = open_sweep(tmp_path / "raise")
    assert list(ds.status.values) == ["error", "finished"]
    assert np.isnan(_local(ds, "y")[0]).all() and np.isfinite(_local(ds, "y")[1]).all()
    assert "ParameterError" in task_paths(tmp_path / "raise", bad.id).log.read_text()
    assert status(tmp_path / "raise")["errors"] == {bad.id: res.errors[bad.id]}
    assert main(["info", str(tmp_path / "fail")]) == 0
    out = capsys.readouterr().out
    assert re.search(r"members +3 in 1 task\n", out) and "member 1" in out
    assert "failed at step 0: diverged" in out
    assert main(["info", "--json", str(tmp_path / "raise")]) == 0
    assert json.loads(capsys.readouterr().out)["errors"] == res.errors


def _scramble(path: Path) -> None:
    """Change bytes in the middle of a file, keeping its size."""
    data = bytearray(path.read_bytes())
    mid = len(data) // 2
    data[mid : mid + 64] = bytes(b ^ 0x5A for b in data[mid : mid + 64])
    path.write_bytes(bytes(data))


def _truncate(path: Path) -> None:
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


def test_a_rerun_redoes_every_task_whose_files_do_not_hold(client, tmp_path: Path) -> None:
    spec = read_spec(RIGID | {"members_per_task": 1, "grid": {"seed": {"start": 0, "stop": 6}}})
    iso.sweep.run(spec, tmp_path, client=client, progress=False)
    t = [task_paths(tmp_path, task.id) for task in spec.tasks]
    ids = [task.id for task in spec.tasks]
    t[0].json.unlink()  # the summary deleted: resumed from the complete file
    t[1].h5.unlink()  # the result file deleted, its summary left
    _truncate(t[2].h5)
    _scramble(t[3].h5)  # same size: only the recorded SHA-256 tells
    t[4].h5.write_bytes(t[5].h5.read_bytes())  # another task's file under this task's name
    t[4].json.unlink()
    forged = json.loads(t[5].json.read_text())
    forged["status"] = ["failed"]
    t[5].json.write_text(json.dumps(forged))
    res = iso.sweep.run(spec, tmp_path, client=client, progress=False)
    assert res.skipped == [] and sorted(res.computed) == sorted(ids) and res.success
    assert sorted(res.redone) == sorted([ids[1], ids[2], ids[3], ids[5]])
    assert "result file" in res.redone[ids[1]] and "is missing" in res.redone[ids[1]]
    assert "changed size" in res.redone[ids[2]]
    assert res.redone[ids[3]].endswith(f"its result file {ids[3]}.h5 changed")
    assert "checksum does not match" in res.redone[ids[5]]
    assert "resumed" in t[0].log.read_text()
    assert "is not this task's result file; starting again" in t[4].log.read_text()
    _assert_members_are_serial_runs(spec, tmp_path)


def test_tasks_are_submitted_lazily_and_progress_is_printed(
    client, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """At most the in-flight bound of tasks is ever waiting, each carrying its own members."""
    from isoflow.sweep import submit as sweep_submit

    class Watching:
        def __init__(self) -> None:
            self.futures: list = []
            self.most = 0
            self.members: list[int] = []

        def nthreads(self) -> dict:
            return client.nthreads()

        def submit(self, fn, spec, *args, **kwargs):
            self.members.append(len(spec.members))
            self.most = max(self.most, 1 + sum(not f.done() for f in self.futures))
            fut = client.submit(fn, spec, *args, **kwargs)
            self.futures.append(fut)
            return fut

    monkeypatch.setattr(sweep_submit, "_in_flight", lambda c: 2)
    spec = read_spec(RIGID | {"members_per_task": 1, "n_steps": 40})
    watching = Watching()
    res = iso.sweep.run(spec, tmp_path, client=watching, progress=True)
    assert res.success and len(res.computed) == len(spec.tasks) == 5
    assert watching.members == [1] * 5 and watching.most == 2
    err = capsys.readouterr().err.splitlines()
    assert err[0] == f"{tmp_path}: 5 members in 5 tasks"
    assert err[-1] == "tasks done 5/5, members failed 0"


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
        target=lambda: out.update(
            r=iso.sweep.run(spec, tmp_path / "k", client=client, progress=False)
        )
    )
    th.start()
    tid, pid = _running_task(tmp_path / "k", spec)
    os.kill(pid, signal.SIGKILL)
    th.join(120)
    res = out["r"]
    assert res.success and len(res.computed) == len(spec.tasks)
    log = task_paths(tmp_path / "k", tid).log.read_text()
    assert log.count("start:") == 1 and "resumed" in log, log
    iso.sweep.run(spec, tmp_path / "ref", client=client, progress=False)
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
    again = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
    assert again.returncode == 0, again.stderr
    assert f"{len(done)} already done" in again.stdout
    for tid, text in done.items():  # not recomputed
        assert task_paths(d, tid).json.read_text() == text
    logs = {t.id: _read_log(d, t.id) for t in spec.tasks}
    assert any("resumed" in text for text in logs.values()), logs
    iso.sweep.run(spec, tmp_path / "ref", client=client, progress=False)
    _assert_same_results(d, tmp_path / "ref")
