"""Fault injection on result files (issue 16): a full disk, failing writes, kills at random
writes and moments, two writers, garbage bytes, crafted fields.

After each fault there is either a clean one-line error or a file that resumes to the
uninterrupted run's states bit for bit; never a file that claims more than it holds. Seeded.
"""

from __future__ import annotations

import errno
import json
import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

import isoflow as iso
from cli_helpers import isoflow_cmd, one_error_line, run_cli, run_cli_here
from helpers import disk_before_sampled_writes
from isoflow import io
from isoflow.io import safefile
from isoflow.io.layout import header_crc, slot_crc

CFG = iso.registry.normalize_config(
    {"model": "rigid-body", "params": {"n": 4}, "dt": 0.01, "n_steps": 1500, "save_every": 3}
)
CHUNK = 16


def _solve(path: Path, **writer_kw: object) -> iso.Solution:
    problem, y0, method, kw = iso.registry.build(CFG)
    writer = io.HDF5Writer(path, CFG, chunk_rows=CHUNK, flush_seconds=0.01, **writer_kw)
    return iso.solve(problem, method, y0, **kw, progress=False, writer=writer)


@pytest.fixture(scope="module")
def ref(tmp_path_factory: pytest.TempPathFactory) -> io.RunData:
    path = tmp_path_factory.mktemp("ref") / "ref.h5"
    _solve(path)
    return io.load(path)


def _leftovers(directory: Path) -> list[str]:
    return sorted(
        p.name for p in directory.iterdir() if p.suffix in (".partial", ".lock", ".recover")
    )


def _resumes_bit_for_bit(path: Path, ref: io.RunData) -> None:
    """``path`` holds a prefix of ``ref``; resuming it gives ``ref`` bit for bit."""
    part = io.load(path)
    assert part.ys.tobytes() == ref.ys[: len(part.ys)].tobytes()
    assert io.info(path)["state"] in ("killed", "stopped", "complete")
    sol = io.resume(path, progress=False)
    assert sol.success
    got = io.load(path)
    assert got.complete and got.run_info is not None and got.run_info["status"] == 0
    assert got.ys.tobytes() == ref.ys.tobytes() and got.ts.tobytes() == ref.ts.tobytes()
    assert got.drifts == ref.drifts
    assert io.info(path, verify_states=True)["state"] == "complete"


# ---- writes that fail after K bytes ------------------------------------------------------------


@pytest.mark.parametrize("code", [errno.ENOSPC, errno.EIO])
def test_writes_failing_after_k_bytes_stop_the_run_and_resume(
    tmp_path: Path, ref: io.RunData, monkeypatch: pytest.MonkeyPatch, code: int
) -> None:
    rng = np.random.default_rng(code)
    _solve(tmp_path / "probe.h5")
    size = (tmp_path / "probe.h5").stat().st_size
    resumed = 0
    for i, limit in enumerate(rng.integers(100, size, 5)):

        def hook(
            sf: safefile.SafeFile, offset: int, data: bytes, limit: int = int(limit),
            written: list[int] = [0],  # noqa: B006 - one counter per hook, by design
        ) -> None:  # fmt: skip
            written[0] += len(data)
            if written[0] > limit:
                raise OSError(code, "injected failure")

        monkeypatch.setattr(safefile, "write_hook", hook)
        path = tmp_path / f"run{i}.h5"
        with pytest.raises(iso.ResultWriteError, match="writing failed") as err:
            _solve(path)
        monkeypatch.setattr(safefile, "write_hook", None)
        assert "\n" not in str(err.value)
        assert _leftovers(tmp_path) == []
        if path.exists():  # published before the failure: the run up to its last checkpoint
            assert "can be resumed" in str(err.value)
            _resumes_bit_for_bit(path, ref)
            resumed += 1
    assert resumed >= 2


# ---- a kill at random writes -------------------------------------------------------------------


def test_a_kill_at_any_write_leaves_a_file_that_resumes(tmp_path: Path, ref: io.RunData) -> None:
    final = tmp_path / "run.h5"
    with disk_before_sampled_writes(final, 12, np.random.default_rng(7)) as seen:
        _solve(final)
    assert seen["writes"] >= 50 and len(seen["copies"]) == 12, seen["writes"]
    for i, data in enumerate(seen["copies"]):
        path = tmp_path / f"kill{i}.h5"
        path.write_bytes(data)
        _resumes_bit_for_bit(path, ref)


# ---- a full disk (RLIMIT_FSIZE) ----------------------------------------------------------------

_LIMITED = textwrap.dedent(
    """
    import resource, signal, sys
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # EFBIG instead of a signal
    resource.setrlimit(resource.RLIMIT_FSIZE, ({limit}, resource.RLIM_INFINITY))
    {body}
    """
)


def _limited(limit: int, body: str) -> subprocess.CompletedProcess[str]:
    code = _LIMITED.format(limit=limit, body=textwrap.dedent(body))
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=600, check=False,
        env={**os.environ, "OPENBLAS_NUM_THREADS": "1"},
    )  # fmt: skip


def test_a_full_disk_stops_the_run_cleanly_and_the_file_resumes(
    tmp_path: Path, ref: io.RunData
) -> None:
    rng = np.random.default_rng(11)
    body = f"""
        import isoflow as iso
        from isoflow import io
        cfg = {json.dumps(CFG)!r}
        import json
        cfg = json.loads(cfg)
        problem, y0, method, kw = iso.registry.build(cfg)
        try:
            iso.solve(problem, method, y0, **kw, progress=False,
                      writer=io.HDF5Writer(sys.argv[1] if len(sys.argv) > 1 else "{{path}}", cfg,
                                           chunk_rows={CHUNK}, flush_seconds=0.01))
        except iso.ResultWriteError as exc:
            print("stopped:", exc)
        else:
            print("completed")
    """
    size = ref.ys.nbytes
    resumed = 0
    for i, limit in enumerate(rng.integers(2_000, size, 3)):
        path = tmp_path / f"full{i}.h5"
        out = _limited(int(limit), body.replace("{path}", str(path)))
        assert out.returncode == 0 and out.stderr == "", out.stderr[-2000:]
        assert out.stdout.startswith("stopped:") and "completed" not in out.stdout, out.stdout
        assert _leftovers(tmp_path) == []
        if path.exists():
            _resumes_bit_for_bit(path, ref)
            resumed += 1
    assert resumed >= 1


CLI_RUN = ["run", "rigid-body", "--n", "4", "--dt", "0.01", "--save-every", "3", "--quiet"]


def test_a_full_disk_through_the_cli(tmp_path: Path) -> None:
    path = tmp_path / "cli.h5"
    args = [*CLI_RUN, "--n-steps", "6000", "--chunk-rows", "16", "--out", str(path)]
    body = f"from isoflow.cli import main; sys.exit(main({args!r}))"
    out = _limited(60_000, body)
    assert out.returncode == 1, out.stdout + out.stderr
    line = one_error_line(out.stderr)
    assert "can be resumed" in line and "completed" not in out.stdout
    assert _leftovers(tmp_path) == []
    assert io.info(path)["resumable"]
    done = run_cli("run", "--resume", str(path), "--quiet")
    assert done.returncode == 0, done.stderr
    assert io.info(path)["state"] == "complete"
    shown = run_cli("info", "--verify", str(path))
    assert shown.returncode == 0 and "every saved state verified" in shown.stdout
    assert re.search(r"^  state +complete", shown.stdout, re.M)


# ---- SIGINT / SIGKILL of isoflow run at random moments, and two writers ----------------------

LONG = [*CLI_RUN, "--n-steps", "48000", "--chunk-rows", "16", "--flush-seconds", "0.05"]


@pytest.fixture(scope="module")
def long_ref(tmp_path_factory: pytest.TempPathFactory) -> io.RunData:
    path = tmp_path_factory.mktemp("long") / "ref.h5"
    out = run_cli(*LONG, "--out", str(path))
    assert out.returncode == 0, out.stderr
    return io.load(path)


def _wait_live(path: Path, proc: subprocess.Popen[bytes]) -> dict:
    deadline = time.monotonic() + 600  # a guard against a hang, not a timing
    while time.monotonic() < deadline:
        assert proc.poll() is None, "the run finished before the test could act; make it longer"
        if path.exists():
            try:
                data = io.info(path)
            except io.ResultFileError:
                data = {}
            if data.get("state") == "live" and data["n_saved"] > 10:
                return data
        time.sleep(0.02)
    raise AssertionError("the run never became live")


def test_a_second_writer_gets_a_clear_error(tmp_path: Path) -> None:
    path = tmp_path / "live.h5"
    forever = [*CLI_RUN, "--n-steps", "5000000", "--flush-seconds", "0.05", "--out", str(path)]
    proc = subprocess.Popen(isoflow_cmd(*forever), stdout=subprocess.DEVNULL)
    try:
        data = _wait_live(path, proc)
        assert data["writer"].startswith(f"pid {proc.pid} ") and not data["resumable"]
        with pytest.raises(io.ResultFileError, match=f"being written by pid {proc.pid}"):
            io.resume(path, progress=False)
        with pytest.raises(io.ResultFileError, match=f"pid {proc.pid}"):
            _solve(path, force=True)
        out = run_cli("run", "--resume", str(path), "--quiet")
        assert out.returncode == 1 and f"pid {proc.pid}" in one_error_line(out.stderr)
        shown = run_cli("info", str(path))
        assert "live" in shown.stdout and f"pid {proc.pid}" in shown.stdout, shown.stderr
    finally:
        proc.kill()
        proc.wait()
    after = io.info(path)  # the lock died with its writer
    assert after["state"] == "killed" and after["resumable"] and after["writer"] is None


def test_sigterm_stops_a_run_as_ctrl_c_does(tmp_path: Path, long_ref: io.RunData) -> None:
    """A batch system's time limit sends SIGTERM: the run checkpoints and closes its file
    (stopped, no lock left), says so in one line, exits 143, and resumes bit for bit."""
    path = tmp_path / "term.h5"
    proc = subprocess.Popen(
        isoflow_cmd(*LONG, "--out", str(path)), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
    )
    _wait_live(path, proc)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=600)
    assert proc.returncode == 143 and err.decode().strip() == "isoflow: terminated (SIGTERM)"
    assert _leftovers(tmp_path) == []
    assert io.info(path)["state"] == "stopped"
    _resumes_bit_for_bit(path, long_ref)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGKILL])
def test_signals_at_random_moments(tmp_path: Path, long_ref: io.RunData, sig: int) -> None:
    rng = np.random.default_rng(int(sig))
    for i, delay in enumerate(rng.uniform(0.0, 1.5, 2)):
        path = tmp_path / f"sig{i}.h5"
        proc = subprocess.Popen(
            isoflow_cmd(*LONG, "--out", str(path)),
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
        )  # fmt: skip
        _wait_live(path, proc) if i else None  # the first at any moment, the second while live
        time.sleep(float(delay))
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=600)
        assert b"Exception ignored" not in err, err[-2000:]
        if b"Traceback" in err:  # only Python's own, when SIGINT comes while it imports
            assert err.rstrip().endswith(b"KeyboardInterrupt") and not path.exists(), err[-2000:]
        assert _leftovers(tmp_path) == [] or sig == signal.SIGKILL
        if path.exists():  # a killed writer's stale lock (still there) does not make it "live"
            assert io.info(path)["state"] != "live"
            _resumes_bit_for_bit(path, long_ref)
        for p in [*tmp_path.glob("*.lock"), *tmp_path.glob("*.partial")]:
            p.unlink()


# ---- garbage and crafted fields ----------------------------------------------------------------


def test_garbage_gives_an_error_or_identical_data(tmp_path: Path, ref: io.RunData) -> None:
    good = tmp_path / "good.h5"
    _solve(good)
    raw = good.read_bytes()
    rng = np.random.default_rng(3)
    errors = 0
    for i, offset in enumerate(rng.integers(0, len(raw) - 4096, 24)):
        bad = tmp_path / f"bad{i}.h5"
        data = bytearray(raw)
        data[offset : offset + 4096] = rng.bytes(4096)
        bad.write_bytes(bytes(data))
        t = time.monotonic()
        try:
            run = io.load(bad)
        except iso.IsoflowError as exc:
            assert isinstance(exc, io.ResultFileError) and "\n" not in str(exc)
            errors += 1
        else:
            assert run.ys.tobytes() == ref.ys.tobytes() and run.ts.tobytes() == ref.ts.tobytes()
            assert run.drifts == ref.drifts
            for k, v in ref.series.items():
                assert run.series[k].tobytes() == v.tobytes(), k
        assert time.monotonic() - t < 2.0, offset
    assert errors > 0


def _craft(path: Path, *, config=None, meta=None, index=None, y=None, desc=None, run_info=None):
    """Edit fields of a closed file and recompute its checksums (as a crafted file would)."""
    with h5py.File(path, "r+") as f:
        if config is not None:
            f.attrs["config"] = json.dumps(config)
        if meta is not None:
            f.attrs["meta"] = json.dumps(meta)
        f.attrs["header_crc"] = header_crc(f.attrs["config"], f.attrs["meta"])
        slot = f["checkpoint"][f"slot{int(f['checkpoint']['current'][0])}"]
        idx = np.asarray(slot["index"][:])
        if index is not None:
            idx[: len(index)] = index
        if y is not None:
            slot["y"][...] = y
        for name, value in (("state_desc", desc), ("run_info", run_info)):
            if value is not None:
                slot[name].resize((len(value),))
                slot[name][:] = np.frombuffer(value, dtype=np.uint8)
        parts = {k: bytes(np.asarray(slot[k][:], dtype=np.uint8)) for k in
                 ("state_blob", "state_desc", "failures_msg", "run_info")}  # fmt: skip
        idx[3] = slot_crc(idx, np.asarray(slot["y"][...]), np.asarray(slot["failures"][...]), parts)
        slot["index"][:] = idx


def _off_space(path: Path) -> np.ndarray:
    with h5py.File(path, "r") as f:
        y = np.asarray(f["checkpoint"][f"slot{int(f['checkpoint']['current'][0])}"]["y"][...])
    return y + np.eye(4)


CRAFTED = {
    "rows 1e9": dict(index=[None, 10**9]),
    "rows -5": dict(index=[None, -5]),
    "step 1e9": dict(index=[10**9]),
    "step -5": dict(index=[-5]),
    "list config": dict(config=[1, 2, 3]),
    "list run_info": dict(run_info=b"[1, 2]"),
    "object dtype": dict(
        desc=b'[{"kind": "array", "dtype": "O", "shape": [1], "offset": 0, "nbytes": 8}]'
    ),
    "absurd shape": dict(meta="absurd"),
    "another model": dict(config="toda"),
    "n = 100000": dict(config="huge"),
    "state outside the space": dict(y="off"),
}


@pytest.mark.parametrize("case", list(CRAFTED))
def test_crafted_fields_give_one_line_errors(tmp_path: Path, case: str) -> None:
    path = tmp_path / "crafted.h5"
    problem, y0, method, kw = iso.registry.build({**CFG, "n_steps": 300})
    iso.solve(problem, method, y0, **kw, progress=False,
              writer=io.HDF5Writer(path, {**CFG, "n_steps": 300}, chunk_rows=CHUNK))  # fmt: skip
    kw_ = dict(CRAFTED[case])
    with h5py.File(path, "r") as f:
        cfg, meta = json.loads(f.attrs["config"]), json.loads(f.attrs["meta"])
    if kw_.get("meta") == "absurd":
        kw_["meta"] = {**meta, "state_shape": [100000, 100000], "core_shape": [100000, 100000]}
    if kw_.get("config") == "toda":
        kw_["config"] = {**cfg, "model": "toda"}
    if kw_.get("config") == "huge":
        kw_["config"] = {**cfg, "params": {"n": 100000}}
    if kw_.get("y") == "off":
        kw_["y"] = _off_space(path)
    if "index" in kw_:
        with h5py.File(path, "r") as f:
            idx = f["checkpoint"][f"slot{int(f['checkpoint']['current'][0])}"]["index"][:]
        kw_["index"] = [int(idx[i]) if v is None else v for i, v in enumerate(kw_["index"])]
    _craft(path, **kw_)
    before = path.read_bytes()
    calls = [lambda: io.resume(path, progress=False)]
    if case not in ("another model", "n = 100000", "state outside the space"):
        calls += [lambda: io.info(path), lambda: io.load(path)]
    for call in calls:
        t = time.monotonic()
        with pytest.raises(iso.IsoflowError) as err:
            call()
        assert time.monotonic() - t < 5
        assert "\n" not in str(err.value)
        if case == "state outside the space":
            assert isinstance(err.value, iso.NotInSpaceError)
        elif case in ("another model", "n = 100000"):  # the registry says what is wrong
            assert isinstance(err.value, iso.registry.ConfigError), repr(err.value)
        else:
            assert str(path) in str(err.value)
            assert isinstance(err.value, io.ResultFileError), repr(err.value)
        assert path.read_bytes() == before
    assert _leftovers(tmp_path) == []
    out = run_cli_here("run", "--resume", str(path), "--quiet")  # the command's error too
    assert out.returncode == 1
    one_error_line(out.stderr)
    assert path.read_bytes() == before


def test_resume_with_a_problem_of_another_shape_leaves_the_file(tmp_path: Path) -> None:
    path = tmp_path / "rb.h5"
    _solve(path)
    before = path.read_bytes()
    problem, _y0 = iso.models.rigid_body(n=5)
    with pytest.raises(io.ResultFileError, match="so"):
        io.resume(path, problem=problem, method=iso.IsoMP(), progress=False)
    assert path.read_bytes() == before and _leftovers(tmp_path) == []


# ---- replacing what is not a regular file ------------------------------------------------------


def test_output_replaced_only_if_it_is_a_regular_file(tmp_path: Path) -> None:
    (tmp_path / "dir.h5").mkdir()
    for target in (tmp_path / "dir.h5", Path("/dev/null")):
        with pytest.raises(io.ResultFileError, match="not replacing it"):
            io.HDF5Writer(target, CFG, force=True)
    (tmp_path / "dangling.h5").symlink_to(tmp_path / "nowhere.h5")
    with pytest.raises(io.ResultFileError, match="symlink"):
        io.HDF5Writer(tmp_path / "dangling.h5", CFG, force=True)
    existing = tmp_path / "old.h5"
    existing.write_text("keep me")
    with pytest.raises(io.ResultFileError, match="exists"):
        io.HDF5Writer(existing, CFG)
    out = run_cli(*CLI_RUN, "--n-steps", "30", "--out", str(tmp_path / "dir.h5"), "--force")
    assert out.returncode == 1 and "not replacing" in one_error_line(out.stderr)
    assert (tmp_path / "dir.h5").is_dir() and _leftovers(tmp_path) == []
    link = tmp_path / "link.h5"
    link.symlink_to(existing)
    _solve(link, force=True)  # through the symlink: its target is replaced, the link stays
    assert link.is_symlink() and io.info(link)["state"] == "complete"
