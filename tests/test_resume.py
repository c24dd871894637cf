"""A streaming ``isoflow run`` killed with SIGKILL leaves a readable file; resuming it (even after
a second kill) gives the uninterrupted run's states bit for bit."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import numpy as np

from cli_helpers import isoflow_cmd as _cmd
from cli_helpers import kill_when as _kill_when
from isoflow import io

ARGS = [
    "run",
    "rigid-body",
    "--n",
    "4",
    "--dt",
    "0.01",
    "--n-steps",
    "48000",  # long enough (about 5 s) to be killed while it runs
    "--save-every",
    "3",
    "--chunk-rows",
    "16",
    "--flush-seconds",
    "0.05",
    "--quiet",
]


def test_sigkill_then_resume_is_bit_for_bit(tmp_path: Path) -> None:
    full = tmp_path / "full.h5"
    out = subprocess.run(_cmd(*ARGS, "--out", str(full)), capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    ref = io.load(full)
    assert ref.complete and len(ref.ys) == 16001

    path = tmp_path / "killed.h5"
    proc = subprocess.Popen(_cmd(*ARGS, "--out", str(path)), stderr=subprocess.DEVNULL)
    seen = _kill_when(path, 300, proc)
    # the killed file opens and holds every state written before the kill, equal to the
    # uninterrupted run's
    part = io.load(path)
    assert not part.complete and part.run_info is None
    assert len(part.ys) >= seen and part.step == 3 * (len(part.ys) - 1)
    assert np.array_equal(part.ys, ref.ys[: len(part.ys)])
    shown = subprocess.run(_cmd("info", str(path)), capture_output=True, text=True).stdout
    assert "killed?" in shown and re.search(r"^  resumable +yes$", shown, re.M)

    # resume, kill the resumed run again, resume again
    assert io.info(path)["meta"]["writer"] == {"chunk_rows": 16, "flush_seconds": 0.05}
    proc = subprocess.Popen(  # writes with the recorded 16 rows and 0.05 s
        _cmd("run", "--resume", str(path), "--quiet"), stderr=subprocess.DEVNULL
    )
    _kill_when(path, len(part.ys) + 200, proc)
    out = subprocess.run(
        _cmd("run", "--resume", str(path), "--quiet"), capture_output=True, text=True
    )
    assert out.returncode == 0, out.stderr
    got = io.load(path)
    assert got.complete and got.run_info["status"] == 0
    assert got.ys.tobytes() == ref.ys.tobytes() and np.array_equal(got.ts, ref.ts)
    assert got.drifts == ref.drifts
    st = got.run_info["stats"]  # the counters are the last call's, and say which steps
    assert st["n_steps"] == 48000 and 0 < st["first_step"] < 48000
    assert st["iterations_mean"] == st["n_iterations"] / (48000 - st["first_step"])
    shown = subprocess.run(_cmd("info", str(path)), capture_output=True, text=True).stdout
    assert f"steps {st['first_step'] + 1} to 48000: the resumed part" in shown


def test_resuming_a_complete_run_changes_nothing(tmp_path: Path) -> None:
    """A complete file has nothing to resume: Python refuses (ResultFileError), the command
    line says so and exits 0; the file keeps its bytes (its statistics are the run's)."""
    import pytest

    import isoflow as iso

    path = tmp_path / "done.h5"
    prob, W0 = iso.models.rigid_body(4)
    iso.solve(prob, iso.IsoMP(), W0, dt=0.1, n_steps=30, save_every=10, progress=False,
              writer=io.HDF5Writer(path))  # fmt: skip
    before = path.read_bytes()
    with pytest.raises(iso.ResultFileError, match=r"the run is complete \(30 of 30 steps\)"):
        io.resume(path)
    out = subprocess.run(_cmd("run", "--resume", str(path)), capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert "the run is complete (30 of 30 steps); nothing to resume" in out.stdout
    assert path.read_bytes() == before
