"""A resume notices a changed model (issue 25): the file records a fingerprint of the model when
its run starts (``B`` and the diagnostics' functions at a probe state, the source of user code)
and a resume with another model is refused with a one-line :class:`iso.ModelChangedError`,
unless forced. Files without a fingerprint resume as before."""

from __future__ import annotations

import dataclasses
import importlib
import json
import sys
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest

import isoflow as iso
from helpers import disk_before_each_write, write_user_model
from isoflow import io
from isoflow._fingerprint import fingerprint_changes, model_fingerprint
from isoflow.io.layout import header_crc
from isoflow.io.safefile import ReadView

RUN = {"dt": 0.01, "n_steps": 60, "save_every": 2}


def fresh_import(name: str) -> Any:
    """Import the module ``name`` again from its source (as a new process would)."""
    sys.modules.pop(name, None)
    importlib.invalidate_caches()
    return importlib.import_module(name)


@pytest.fixture
def user_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(sys, "dont_write_bytecode", True)  # edits within a second are seen
    return tmp_path


def killed_run(problem: Any, y0: Any, path: Path) -> Path:
    """A file as a SIGKILL in the middle of the run of ``problem`` leaves it (at a write)."""
    full = path.with_name("full.h5")
    with disk_before_each_write(full) as copies:
        iso.solve(problem, iso.IsoMP(), y0, **RUN, progress=False,
                  writer=io.HDF5Writer(full, chunk_rows=2, flush_seconds=0.0))  # fmt: skip
    path.write_bytes(copies[len(copies) // 2])
    assert 0 < io.load(path).step < RUN["n_steps"]
    return path


def test_a_changed_b_is_refused_and_force_resumes(user_dir: Path) -> None:
    write_user_model(user_dir, "fp_model")
    problem, y0 = fresh_import("fp_model").factory()
    path = killed_run(problem, y0, user_dir / "run.h5")
    before = path.read_bytes()

    write_user_model(user_dir, "fp_model", factor="-2.0 * ")  # the user edits B
    changed, _ = fresh_import("fp_model").factory()
    with pytest.raises(iso.ModelChangedError) as err:
        io.resume(path, problem=changed, method=iso.IsoMP(), progress=False)
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith(f"{path}: the model changed since the run started")
    assert "B differs at the probe state by 5.0e-01 (relative)" in msg
    assert "the source of module fp_model changed" in msg and "force=True" in msg
    assert err.value.changes == [
        "B differs at the probe state by 5.0e-01 (relative)",
        "the source of module fp_model changed",
    ]
    assert isinstance(err.value, io.ResultFileError) and path.read_bytes() == before

    sol = io.resume(path, problem=changed, method=iso.IsoMP(), progress=False, force=True)
    assert sol.success and io.load(path).complete


def test_an_edit_of_the_module_alone_is_named(user_dir: Path) -> None:
    write_user_model(user_dir, "fp_edit")
    problem, y0 = fresh_import("fp_edit").factory()
    path = killed_run(problem, y0, user_dir / "run.h5")
    write_user_model(user_dir, "fp_edit", comment="# a comment\n")
    same, _ = fresh_import("fp_edit").factory()
    with pytest.raises(iso.ModelChangedError) as err:
        io.resume(path, problem=same, method=iso.IsoMP(), progress=False)
    assert err.value.changes == ["the source of module fp_edit changed"]
    write_user_model(user_dir, "fp_edit")  # restored: resumes bit for bit
    again, _ = fresh_import("fp_edit").factory()
    assert io.resume(path, problem=again, method=iso.IsoMP(), progress=False).success
    assert io.load(path).ys.tobytes() == io.load(user_dir / "full.h5").ys.tobytes()


def _scaled(problem: Any, factor: float, **fields: Any) -> Any:
    """``problem`` with ``B`` times ``factor`` (a function of this module, as the original's)."""
    B = problem.B
    return dataclasses.replace(problem, B=lambda W: factor * B(W), **fields)


def test_rounding_passes_and_a_small_change_does_not(tmp_path: Path) -> None:
    base, y0 = iso.models.rigid_body(n=4)
    problem = _scaled(base, 1.0, kernel=None)
    path = killed_run(problem, y0, tmp_path / "run.h5")
    fp = model_fingerprint(problem, y0)
    assert fingerprint_changes(fp, model_fingerprint(_scaled(base, 1 + 1e-13), y0)) == []
    with pytest.raises(iso.ModelChangedError, match=r"B differs .* by 1\.0e-06 \(relative\)"):
        io.resume(path, problem=_scaled(base, 1 + 1e-6, kernel=None), method=iso.IsoMP(),
                  progress=False)  # fmt: skip
    assert io.resume(path, problem=_scaled(base, 1 + 1e-13, kernel=None), method=iso.IsoMP(),
                     progress=False).success  # fmt: skip


def test_the_diagnostics_functions_and_a_compiled_b_are_part_of_the_model(tmp_path: Path) -> None:
    import user_kernels

    alg = iso.algebras.so(4)
    C = np.add.outer(np.arange(4.0), np.arange(4.0))
    problem = iso.IsospectralProblem(
        algebra=alg, kernel=iso.CompiledB(user_kernels.cubic_elementwise, (C,)),
        hamiltonian=lambda W: np.sum(W * W, axis=(-2, -1)),
    )  # fmt: skip
    y0 = alg.random(0, scale=0.3)
    fp = model_fingerprint(problem, y0)
    assert list(fp["sources"]) == ["module user_kernels"]
    doubled = dataclasses.replace(
        problem, B=None, kernel=iso.CompiledB(user_kernels.cubic_elementwise, (2 * C,))
    )
    assert fingerprint_changes(fp, model_fingerprint(doubled, y0)) == [
        "B differs at the probe state by 5.0e-01 (relative)"
    ]
    other_h = dataclasses.replace(problem, hamiltonian=lambda W: np.sum(W**4, axis=(-2, -1)))
    (change,) = fingerprint_changes(fp, model_fingerprint(other_h, y0))
    assert change.startswith("hamiltonian differs at the probe state by")
    no_h = dataclasses.replace(problem, hamiltonian=None)
    assert fingerprint_changes(fp, model_fingerprint(no_h, y0)) == [
        "the model no longer has its hamiltonian"
    ]


def test_files_without_a_fingerprint_resume_as_before(tmp_path: Path) -> None:
    base, y0 = iso.models.rigid_body(n=4)
    path = killed_run(base, y0, tmp_path / "old.h5")
    view = ReadView(path)  # the killed file's bytes as if its writer had closed it, to edit
    data = bytearray(path.stat().st_size)
    view.readinto(data)
    view.close()
    path.write_bytes(bytes(data))
    with h5py.File(path, "r+") as f:  # as written before fingerprints existed
        meta = json.loads(f.attrs["meta"])
        del meta["model_fingerprint"]
        f.attrs["meta"] = json.dumps(meta)
        f.attrs["header_crc"] = header_crc(f.attrs["config"], f.attrs["meta"])
    sol = io.resume(path, problem=_scaled(base, 2.0, kernel=None), method=iso.IsoMP(),
                    progress=False)  # fmt: skip
    assert sol.success


def test_changed_method_settings_are_refused_and_force_resumes(tmp_path: Path) -> None:
    """The method's name was the only check: a resume with another tolerance or compensation
    continued the run on another path without a word."""
    base, y0 = iso.models.rigid_body(n=4)
    path = killed_run(base, y0, tmp_path / "run.h5")
    before = path.read_bytes()
    full = io.load(tmp_path / "full.h5")
    for method, change in (
        (iso.IsoMP(solver=iso.FixedPoint(rtol=1e-10)), "solver.rtol: 1e-14 -> 1e-10"),
        (iso.IsoMP(compensated=False), "compensated: True -> False"),
        (iso.IsoMP(extrapolation_order=2), "extrapolation_order: None -> 2"),
        (iso.IsoMP(solver=iso.Newton()), "solver.class: 'FixedPoint' -> 'Newton'"),
    ):
        with pytest.raises(iso.ResultFileError) as err:
            io.resume(path, problem=base, method=method, progress=False)
        msg = str(err.value)
        assert "\n" not in msg and "the method's settings changed" in msg and change in msg, msg
        assert path.read_bytes() == before  # untouched
    forced = io.resume(path, problem=base, method=iso.IsoMP(compensated=False), progress=False,
                       force=True)  # fmt: skip
    assert forced.success
    (tmp_path / "b").mkdir()
    again = killed_run(base, y0, tmp_path / "b" / "again.h5")
    io.resume(again, problem=base, method=iso.IsoMP(), progress=False)  # the same settings
    assert io.load(again).ys.tobytes() == full.ys.tobytes()


def test_files_without_method_settings_resume_as_before(tmp_path: Path) -> None:
    base, y0 = iso.models.rigid_body(n=4)
    path = killed_run(base, y0, tmp_path / "old.h5")
    view = ReadView(path)
    data = bytearray(path.stat().st_size)
    view.readinto(data)
    view.close()
    path.write_bytes(bytes(data))
    with h5py.File(path, "r+") as f:  # as written before method settings were recorded
        meta = json.loads(f.attrs["meta"])
        del meta["method_settings"]
        f.attrs["meta"] = json.dumps(meta)
        f.attrs["header_crc"] = header_crc(f.attrs["config"], f.attrs["meta"])
    method = iso.IsoMP(solver=iso.FixedPoint(rtol=1e-12))
    assert io.resume(path, problem=base, method=method, progress=False).success


def test_b_undefined_near_the_initial_state_is_probed_at_it() -> None:
    base, y0 = iso.models.rigid_body(n=3)

    def only_at_the_start(W: Any) -> Any:
        if not np.array_equal(W, y0):
            raise ValueError("B is defined at the initial state only")
        return base.B(W)

    fp = model_fingerprint(dataclasses.replace(base, B=only_at_the_start, kernel=None), y0)
    assert fp["probe"] == "initial" and fp["values"]["B"] is not None
    assert fingerprint_changes(fp, model_fingerprint(base, y0)) == [
        "B is now defined at the probe state, where it was not",
        "the source of module test_model_fingerprint changed",  # B is isoflow's now
    ]


@pytest.mark.parametrize(
    "recorded",
    [
        {"version": 1, "probe": "perturbed", "values": {"B": "garbage"}, "sources": []},
        {"version": 1, "probe": 3, "values": [], "sources": {"module x": 1}},
        {"version": 1, "values": {"B": [[1.0]]}},
    ],
)
def test_malformed_records_are_named_not_raised(recorded: dict) -> None:
    problem, y0 = iso.models.rigid_body(n=3)
    changes = fingerprint_changes(recorded, model_fingerprint(problem, y0))
    assert changes and all(isinstance(c, str) and "\n" not in c for c in changes)
    assert fingerprint_changes({"version": 99}, model_fingerprint(problem, y0)) == []


def test_a_sweep_task_with_a_changed_model_is_refused(user_dir: Path) -> None:
    from isoflow.sweep import read_spec
    from isoflow.sweep.files import task_paths
    from isoflow.sweep.task import run_task

    write_user_model(user_dir, "fp_sweep")
    spec = read_spec({"model": "fp_sweep:factory", **RUN, "members": [{"n": 4}]})
    (task,) = spec.tasks
    paths = task_paths(user_dir / "sweep", task.id)
    with disk_before_each_write(paths.h5) as copies:
        run_task(spec, task.id, user_dir / "sweep")
    paths.json.unlink()  # killed in the middle: no summary, a file with a checkpoint
    paths.h5.write_bytes(copies[len(copies) // 2])
    write_user_model(user_dir, "fp_sweep", factor="-2.0 * ")
    fresh_import("fp_sweep")
    with pytest.raises(iso.ModelChangedError) as err:
        run_task(spec, task.id, user_dir / "sweep")
    assert str(err.value) == (
        f"{paths.h5}: the model changed since this task started (B differs at the probe state "
        "by 5.0e-01 (relative); the source of module fp_sweep changed); resuming would mix two "
        "models in one task: restore the model, or delete this file to run the task again "
        "from its start with this one"
    )  # a sweep has no force: isoflow run --resume refuses a task's file
    assert not paths.json.exists() and "the model changed" in paths.log.read_text()
    paths.h5.unlink()  # as the message says
    assert run_task(spec, task.id, user_dir / "sweep")["status"] == ["finished"]
