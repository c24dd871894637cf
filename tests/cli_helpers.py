"""Running the ``isoflow`` command in a subprocess, shared by the command-line tests."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

TESTS = Path(__file__).resolve().parent


def isoflow_cmd(*args: str) -> list[str]:
    """The command line of ``isoflow ARGS`` (the installed script, else ``python -m``)."""
    exe = shutil.which("isoflow")
    return [exe, *args] if exe else [sys.executable, "-m", "isoflow.cli", *args]


def user_env() -> dict[str, str]:
    """The environment with this directory on ``PYTHONPATH`` (for ``--model user_models:...``)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(TESTS), env.get("PYTHONPATH")) if p)
    return env


def run_cli(
    *args: str, cwd: Path | None = None, env: dict[str, str] | None = None, timeout: float = 300
) -> subprocess.CompletedProcess[str]:
    """Run ``isoflow ARGS`` to completion, capturing its output."""
    return subprocess.run(
        isoflow_cmd(*args), capture_output=True, text=True, timeout=timeout, check=False,
        cwd=cwd, env=env,
    )  # fmt: skip


def kill_when(path: Path, min_rows: int, proc: subprocess.Popen) -> int:
    """SIGKILL ``proc`` once the result file ``path`` holds ``min_rows`` states; return them."""
    from isoflow import io

    deadline = time.monotonic() + 600  # a guard against a hang, not a timing
    n = 0
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise AssertionError("the run finished before it could be killed; make it longer")
        try:
            n = io.info(path)["n_saved"] if path.exists() else 0
        except io.ResultFileError:
            n = 0  # the file is being created
        if n >= min_rows:
            break
        time.sleep(0.02)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert proc.returncode == -signal.SIGKILL
    return n


def one_error_line(stderr: str) -> str:
    """The single ``isoflow...: error: ...`` line of ``stderr`` (asserting there is one)."""
    assert "Traceback" not in stderr, stderr
    lines = [ln for ln in stderr.strip().splitlines() if ln.startswith("isoflow")]
    lines = [ln for ln in lines if "error" in ln]
    assert len(lines) == 1, stderr
    return lines[0]
