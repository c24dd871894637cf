"""Streaming to HDF5 (``solve(writer=...)``), readers, export, resume in-process, bounded memory."""

from __future__ import annotations

import dataclasses
import gc
import importlib
import json
import tracemalloc
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest

import isoflow as iso
from isoflow import io
from isoflow.diagnostics import DiagnosticsAccumulator, compute_diagnostics
from isoflow.io.codec import pack_state as _pack_state
from isoflow.io.codec import unpack_state as _unpack_state

CFG = {"model": "rigid-body", "params": {"n": 5}, "dt": 0.1, "n_steps": 700, "save_every": 3}


def _build(cfg: dict = CFG):
    cfg = iso.registry.normalize_config(cfg)
    problem, y0, method, kw = iso.registry.build(cfg)
    return cfg, problem, y0, method, kw


def test_streamed_run_equals_in_memory_run_bit_for_bit(tmp_path: Path) -> None:
    cfg, problem, y0, method, kw = _build()
    ref = iso.solve(problem, method, y0, **kw, progress=False)
    path = tmp_path / "rb.h5"
    sol = iso.solve(
        problem, method, y0, **kw, progress=False, writer=io.HDF5Writer(path, cfg, chunk_rows=16)
    )
    # the returned Solution holds the first and the final state only
    assert sol.ys.shape == (2, 5, 5)
    assert np.array_equal(sol.ys[-1], ref.ys[-1]) and sol.ts[-1] == ref.ts[-1]
    run = io.load(path)
    assert np.array_equal(run.ys, ref.ys) and np.array_equal(run.ts, ref.ts)
    assert run.complete and run.step == 700 and run.run_info["status"] == 0
    # drifts: incremental == batch, in the Solution and recomputed from the file
    assert sol.diagnostics.summary() == ref.diagnostics.summary()
    for key, value in ref.diagnostics.summary().items():
        assert run.drifts[key] == pytest.approx(value, rel=1e-12, abs=1e-300)
    full = io.solution_diagnostics(run, problem)
    assert np.array_equal(full.hamiltonian, ref.diagnostics.hamiltonian)
    # configuration is JSON text in the attributes
    with h5py.File(path, "r") as f:
        assert json.loads(f.attrs["config"]) == cfg
        assert f.attrs["isoflow_format"] == io.FORMAT


def test_accumulator_matches_compute_diagnostics_in_chunks(rng: np.random.Generator) -> None:
    problem, W0 = iso.models.brockett(n=4, seed=1)
    sol = iso.solve(problem, iso.IsoMP(), W0, dt=0.1, n_steps=60, progress=False)
    ref = compute_diagnostics(problem, sol.ts, sol.ys)
    acc = DiagnosticsAccumulator(problem)
    for lo in range(0, len(sol.ts), 7):  # uneven chunks
        acc.update(sol.ts[lo : lo + 7], sol.ys[lo : lo + 7])
    got = acc.result()
    assert got.summary() == ref.summary()
    assert np.array_equal(got.casimirs[-1], ref.casimirs[-1])


@pytest.mark.parametrize(
    "state",
    [None, (0.1, np.arange(6.0).reshape(2, 3)), (0.5, np.ones((2, 2), complex), 3, None, True)],
)
def test_method_state_round_trip_is_exact(state: object) -> None:
    back = _unpack_state(*_pack_state(state))
    if state is None:
        assert back is None
        return
    assert isinstance(back, tuple) and len(back) == len(state)
    for a, b in zip(state, back, strict=True):
        if isinstance(a, np.ndarray):
            assert a.dtype == b.dtype and a.tobytes() == b.tobytes()
        else:
            assert a == b and type(a) is type(b)


class _Interrupt(Exception):
    pass


def _interrupted_run(path: Path, monkeypatch, **writer: Any) -> Any:
    """The reference run, and ``path`` holding the same run interrupted after three chunks
    (an exception raised by the compiled runner's fourth chunk), written with ``writer``'s
    settings (default: 8 rows a chunk)."""
    from isoflow._compiled.runner import CompiledRunner

    cfg, problem, y0, method, kw = _build()
    ref = iso.solve(problem, method, y0, **kw, progress=False)
    calls = {"n": 0}
    original = CompiledRunner.advance

    def flaky(self, *args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 4:  # in the middle of the run, after three chunks
            raise _Interrupt
        return original(self, *args, **kwargs)

    monkeypatch.setattr(CompiledRunner, "advance", flaky)
    with pytest.raises(_Interrupt):
        iso.solve(
            problem, method, y0, **kw, progress=False,
            writer=io.HDF5Writer(path, cfg, **({"chunk_rows": 8} | writer)),
        )  # fmt: skip
    monkeypatch.setattr(CompiledRunner, "advance", original)
    return ref


def test_interrupted_run_resumes_bit_for_bit(tmp_path: Path, monkeypatch) -> None:
    path = tmp_path / "rb.h5"
    ref = _interrupted_run(path, monkeypatch)
    part = io.info(path)
    # the interrupt kept every chunk done before it: the rows and a checkpoint after them
    assert not part["complete"] and 0 < part["step"] < 700
    assert part["n_saved"] == part["step"] // 3 + 1
    sol = io.resume(path, progress=False)
    assert sol.success and np.array_equal(sol.ys[-1], ref.ys[-1])
    run = io.load(path)
    assert np.array_equal(run.ys, ref.ys) and np.array_equal(run.ts, ref.ts)
    assert sol.diagnostics.summary() == ref.diagnostics.summary()


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"throw": "x"}, r"throw must be True or False, got 'x'"),
        ({"progress": "x"}, r"progress must be True, False or None, got 'x'"),
        ({"status_every": -5}, r"status_every must be a positive number of seconds"),
        ({"chunk_rows": 0}, r"chunk_rows must be an integer >= 1, got 0"),
        ({"flush_seconds": "x"}, r"flush_seconds must be a number of seconds >= 0, got 'x'"),
        ({"force": "yes"}, r"force must be True or False, got 'yes'"),
    ],
)
def test_bad_resume_options_are_refused_before_the_file_is_touched(
    tmp_path: Path,
    monkeypatch,
    kwargs,
    match,  # type: ignore[no-untyped-def]
) -> None:
    """Checked first: the file is not left locked or live (a retry in the same process
    resumed it), and it resumes afterwards."""
    path = tmp_path / "rb.h5"
    ref = _interrupted_run(path, monkeypatch)
    before = path.read_bytes()
    with pytest.raises(iso.ParameterError, match=match):
        io.resume(path, **kwargs)
    assert path.read_bytes() == before and not Path(f"{path}.lock").exists()
    assert io.info(path)["state"] != "live"
    sol = io.resume(path, progress=False)
    assert sol.success and np.array_equal(sol.ys[-1], ref.ys[-1])


def test_resume_of_a_complete_run_changes_nothing(tmp_path: Path) -> None:
    cfg, problem, y0, method, kw = _build()
    path = tmp_path / "rb.h5"
    iso.solve(problem, method, y0, **kw, progress=False, writer=io.HDF5Writer(path, cfg))
    before = io.load(path)
    sol = io.resume(path, progress=False)
    after = io.load(path)
    assert sol.success and np.array_equal(before.ys, after.ys) and after.complete


def test_custom_problem_resumes_with_explicit_problem(tmp_path: Path) -> None:
    alg = iso.algebras.so(3)
    problem = iso.IsospectralProblem(B=lambda W: -W @ W @ W, algebra=alg)
    W0 = alg.random(seed=3)
    path = tmp_path / "custom.h5"
    ref = iso.solve(problem, iso.IsoMP(), W0, dt=0.05, n_steps=40, progress=False)
    iso.solve(
        problem,
        iso.IsoMP(),
        W0,
        dt=0.05,
        n_steps=40,
        progress=False,
        writer=io.HDF5Writer(path, {"note": "my own problem"}),
    )
    with pytest.raises(io.ResultFileError, match="pass problem= and method="):
        io.resume(path)
    sol = io.resume(path, problem=problem, method=iso.IsoMP(), progress=False)
    assert np.array_equal(sol.ys[-1], ref.ys[-1])


def test_xarray_and_netcdf_export(tmp_path: Path) -> None:
    xr = pytest.importorskip("xarray")
    cfg, problem, y0, method, kw = _build(
        {"model": "brockett", "params": {"n": 3}, "dt": 0.1, "n_steps": 20}
    )
    path = tmp_path / "b.h5"
    iso.solve(problem, method, y0, **kw, progress=False, writer=io.HDF5Writer(path, cfg))
    ds = io.to_xarray(path)
    run = io.load(path)
    assert np.array_equal(ds["y_real"].values + 1j * ds["y_imag"].values, run.ys)
    assert np.array_equal(ds["time"].values, run.ts)
    nc = io.to_netcdf(path, tmp_path / "b.nc")
    back = xr.open_dataset(nc, engine="h5netcdf")
    assert np.array_equal(back["y_real"].values, ds["y_real"].values)
    assert json.loads(back.attrs["config"])["model"] == "brockett"
    assert json.loads(back.attrs["run_info"])["status"] == 0
    assert json.loads(back.attrs["drifts"]) == run.drifts
    back.close()
    with pytest.raises(iso.ResultFileError, match="is the result file being exported"):
        io.to_netcdf(path, path)  # replaced the result file by its export
    with pytest.raises(iso.ResultFileError, match=r"b.nc exists \(use --force / force=True") as e:
        io.to_netcdf(path, tmp_path / "b.nc")
    assert "--resume" not in str(e.value)  # an export cannot be resumed
    with pytest.raises(iso.ParameterError, match="force must be True or False"):
        io.to_netcdf(path, tmp_path / "b.nc", force="no")
    with pytest.raises(iso.ResultFileError, match=r"no directory .*nodir to write it in"):
        io.to_netcdf(path, tmp_path / "nodir" / "b.nc")
    assert io.to_netcdf(path, tmp_path / "b.nc", force=True) == tmp_path / "b.nc"
    assert io.info(path)["complete"] and sorted(p.name for p in tmp_path.iterdir()) == [
        "b.h5",
        "b.nc",
    ]  # no partial file left


def test_readers_reject_files_that_are_not_ours(tmp_path: Path) -> None:
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f["x"] = np.arange(3)
    with pytest.raises(io.ResultFileError, match="not an isoflow result file"):
        io.info(other)
    text = tmp_path / "text.h5"
    text.write_text("hello")
    with pytest.raises(io.ResultFileError, match="not an isoflow result file"):
        io.load(text)
    with pytest.raises(io.ResultFileError, match="no such file"):
        io.info(tmp_path / "missing.h5")
    # a truncated result file
    cfg, problem, y0, method, kw = _build()
    good = tmp_path / "good.h5"
    iso.solve(problem, method, y0, **kw, progress=False, writer=io.HDF5Writer(good, cfg))
    cut = tmp_path / "cut.h5"
    cut.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    with pytest.raises(io.ResultFileError):
        io.load(cut)


def _streamed_peak(n_steps: int, path: Path) -> int:
    problem, W0 = iso.models.rigid_body(3)  # compiled steps: the loop's own allocations count
    writer = io.HDF5Writer(path, {}, chunk_rows=64)
    tracemalloc.start()
    try:
        iso.solve(problem, iso.IsoMP(), W0, dt=1e-3, n_steps=n_steps, progress=False,
                  writer=writer)  # fmt: skip
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert io.info(path)["n_saved"] == n_steps + 1
    return peak


def test_streaming_memory_does_not_grow_with_the_number_of_steps(tmp_path: Path) -> None:
    """tracemalloc peak (Python allocations) for 1e3 vs 1e4 steps saving every step.

    Holding the states and series would add about 9000 * 120 B = 1.1 MB; streaming stays within
    512 kB (the residue is h5py selection/ID objects awaiting the cyclic garbage collector, which
    varies with what else the process holds).
    """
    gc.collect()
    _streamed_peak(200, tmp_path / "warm.h5")  # imports and caches outside the measurement
    gc.collect()
    small = _streamed_peak(1_000, tmp_path / "a.h5")
    gc.collect()
    large = _streamed_peak(10_000, tmp_path / "b.h5")
    assert large - small < 512 * 1024, (small, large)


def _to_version_1(path: Path) -> None:
    """Rewrite a closed version 2 file in place as the version 1 format wrote it."""
    with h5py.File(path, "r+") as f:
        cur = int(f["checkpoint"]["current"][0])
        run_info = np.asarray(f["checkpoint"][f"slot{cur}"]["run_info"][:], dtype=np.uint8)
        for i in (0, 1):
            g = f["checkpoint"][f"slot{i}"]
            index = np.asarray(g["index"][:2])
            del g["index"], g["run_info"]
            g.create_dataset("index", data=index)
        del f["checksums"]
        del f.attrs["header_crc"]
        f.attrs["isoflow_format_version"] = 1
        f.create_dataset("run_info", data=run_info, maxshape=(None,), chunks=(1024,))


def test_version_1_files_read_and_resume_to_version_2(tmp_path: Path, monkeypatch) -> None:
    path = tmp_path / "v1.h5"
    ref = _interrupted_run(path, monkeypatch)
    _to_version_1(path)
    part = io.info(path)
    assert part["format_version"] == 1 and part["state"] == "stopped" and part["resumable"]
    run = io.load(path)
    assert np.array_equal(run.ys, ref.ys[: len(run.ys)]) and run.run_info["status"] == 2
    sol = io.resume(path, progress=False)
    assert sol.success and np.array_equal(sol.ys[-1], ref.ys[-1])
    done = io.info(path, verify_states=True)
    assert done["format_version"] == 2 and done["verified"] and done["state"] == "complete"
    assert io.load(path).ys.tobytes() == ref.ys.tobytes()


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"chunk_rows": 2.5}, r"chunk_rows must be an integer >= 1, got 2.5"),
        ({"chunk_rows": "x"}, r"chunk_rows must be an integer >= 1, got 'x'"),
        ({"chunk_rows": 0}, r"chunk_rows must be an integer >= 1, got 0"),
        ({"flush_seconds": -1}, r"flush_seconds must be a number of seconds >= 0, got -1"),
        ({"flush_seconds": float("nan")}, r"flush_seconds must be a number of seconds >= 0"),
        ({"config": {"a": np.zeros(2)}}, r"config must be JSON-ready .*ndarray"),
        ({"force": "no"}, r"force must be True or False, got 'no'"),  # "no" was true
    ],
)
def test_bad_writer_arguments_are_one_line_parameter_errors(tmp_path: Path, kwargs, match) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(iso.ParameterError, match=match):
        io.HDF5Writer(tmp_path / "x.h5", **kwargs)
    assert not (tmp_path / "x.h5").exists()


def test_a_resume_writes_with_the_runs_recorded_chunk_rows_and_flush_interval(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The file records the writer's settings; :func:`isoflow.io.resume` (and so ``isoflow run
    --resume``) writes with them unless given others (a run flushed every 300 s must not be
    resumed into one that writes a checkpoint every second)."""
    resume_module = importlib.import_module("isoflow.io.resume")  # the module, not the function
    seen: list[tuple[int, float]] = []
    reopen = resume_module.HDF5Writer.reopen

    def spy(*args: Any, **kw: Any) -> Any:
        seen.append((kw["chunk_rows"], kw["flush_seconds"]))
        return reopen(*args, **kw)

    for flush, recorded in ((300.0, 300.0), (np.inf, None)):
        paths = [tmp_path / f"run_{flush}_{k}.h5" for k in range(2)]
        for path in paths:  # stopped runs (a complete one is not reopened)
            _interrupted_run(path, monkeypatch, chunk_rows=7, flush_seconds=flush)
            assert io.info(path)["meta"]["writer"] == {"chunk_rows": 7, "flush_seconds": recorded}
        monkeypatch.setattr(resume_module.HDF5Writer, "reopen", spy)
        io.resume(paths[0], progress=False)
        io.resume(paths[1], progress=False, chunk_rows=3, flush_seconds=0.5)
        monkeypatch.undo()
        assert seen[-2:] == [(7, flush), (3, 0.5)]
    assert resume_module._writer_settings({}, None, None) == (256, 1.0)  # an older file


def test_a_resume_with_other_diagnostics_is_refused_even_with_force(
    tmp_path: Path, monkeypatch
) -> None:  # type: ignore[no-untyped-def]
    """A resumed run appends to the file's series: a model whose invariants or observables
    are not the file's is refused with a one-line ResultFileError naming them (force=True used
    to end in a KeyError), and the file is left as it was."""
    path = tmp_path / "rb.h5"
    _interrupted_run(path, monkeypatch)
    _, problem, _, method, _ = _build()
    renamed = dataclasses.replace(
        problem, invariants={"spin": next(iter(problem.invariants.values()))}
        if problem.invariants else {"spin": lambda W: W[..., 0, 1]},
    )  # fmt: skip
    before = path.read_bytes()
    with pytest.raises(iso.ResultFileError, match=r"the model's diagnostics differ") as err:
        io.resume(path, problem=renamed, method=method, force=True, progress=False)
    assert "invariants/spin" in str(err.value) and "\n" not in str(err.value)
    assert path.read_bytes() == before


def test_an_ensembles_export_shares_its_member_dimension(tmp_path: Path) -> None:
    """Every variable of an ensemble's export has the member axis as ``member`` (selectable
    across variables), the values equal the file's, and a failed run's status is kept."""
    from helpers import failed_ensemble_file

    pytest.importorskip("xarray")
    path = failed_ensemble_file(tmp_path / "e.h5", n_steps=20)  # member 1 fails at once
    ds, run = io.to_xarray(path), io.load(path)
    assert ds["y"].dims == ("time", "member", "y_dim0", "y_dim1")
    assert ds["casimirs"].dims == ("time", "member", "casimirs_dim0")
    assert ds["hamiltonian"].dims == ("time", "member")
    assert np.array_equal(ds["y"].sel(member=2).values, run.ys[:, 2])
    assert np.array_equal(ds["hamiltonian"].values, run.series["hamiltonian"])
    info = json.loads(ds.attrs["run_info"])
    assert info["status"] == 1 and "(1,)" in info["message"]


def test_a_run_larger_than_the_free_disk_is_warned_about(tmp_path: Path, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """Not refused (a run may be stopped early), but said before it starts: its saved states
    need more than the disk's free space."""
    import collections
    import shutil

    usage = collections.namedtuple("usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda p: usage(10**6, 10**6 - 1000, 1000))
    prob, W0 = iso.models.rigid_body(4)
    with pytest.warns(UserWarning, match=r"saved states need about .* GiB, more than the"):
        sol = iso.solve(prob, iso.IsoMP(), W0, dt=0.1, n_steps=40, progress=False,
                        writer=io.HDF5Writer(tmp_path / "w.h5"))  # fmt: skip
    assert sol.success  # 41 states of 128 bytes: it still fits, and runs
