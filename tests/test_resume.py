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
    assert "(killed, or a write failed)" in shown and re.search(r"^  resumable +yes$", shown, re.M)

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


def test_resuming_a_run_that_ended_changes_nothing(tmp_path: Path) -> None:
    """A complete or failed file has nothing to continue: resume returns the run as recorded
    (its statistics, not a zero-step call's), the command line says so (exit 0 and 1); the
    file keeps its bytes."""

    path = tmp_path / "done.h5"
    made = subprocess.run(
        _cmd("run", "rigid-body", "--n", "4", "--dt", "0.1", "--n-steps", "30", "--save-every",
             "10", "--out", str(path), "--quiet"), capture_output=True, text=True,
    )  # fmt: skip
    assert made.returncode == 0, made.stderr
    ran = io.load(path)
    before = path.read_bytes()
    again = io.resume(path)
    assert again.stats.as_dict() == ran.run_info["stats"] and again.success
    assert again.message == ran.run_info["message"]
    assert np.array_equal(again.ys[-1], ran.ys[-1]) and again.ts[-1] == ran.ts[-1]
    assert again.diagnostics is not None and again.diagnostics.summary() == ran.drifts
    out = subprocess.run(_cmd("run", "--resume", str(path)), capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert "the run is complete (30 of 30 steps): nothing to resume" in out.stdout
    assert path.read_bytes() == before

    failed = tmp_path / "failed.h5"  # h ||B|| far above 2: the first stage diverges
    made = subprocess.run(
        _cmd("run", "rigid-body", "--n", "4", "--dt", "50", "--n-steps", "30", "--out",
             str(failed), "--quiet"), capture_output=True, text=True,
    )  # fmt: skip
    assert made.returncode == 1 and io.info(failed)["state"] == "failed", made.stderr
    ran = io.load(failed)
    before = failed.read_bytes()
    again = io.resume(failed)
    assert again.stats.as_dict() == ran.run_info["stats"] and not again.success
    assert again.message == ran.run_info["message"] and int(again.failed_step) == 0
    out = subprocess.run(_cmd("run", "--resume", str(failed)), capture_output=True, text=True)
    assert out.returncode == 1 and "the run failed" in out.stdout, out.stderr
    assert failed.read_bytes() == before
