"""Running the ``isoflow`` command, shared by the command-line tests: in a subprocess (what a
user runs; needed to kill it, to see its exit by a signal or its own environment) or in this
process (:func:`run_cli_here`, the same entry point without a new interpreter: for the many
one-line-error checks, about a second each as subprocesses)."""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import sys
import time
from io import StringIO
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


def run_cli_here(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    """Run ``isoflow ARGS`` in this process through :func:`isoflow.cli.main` (what the
    ``isoflow`` script calls), capturing its output; a result like :func:`run_cli`'s.

    For commands that end before computing anything (argument and file mistakes): the
    working directory is changed for the call and restored. ``test_cli_run.py`` checks that
    it gives the installed command's exit status and error line.
    """
    from isoflow.cli import main

    out, err = StringIO(), StringIO()
    here = os.getcwd()
    try:
        if cwd is not None:
            os.chdir(cwd)
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main(list(args))
            except SystemExit as stop:  # argparse's mistakes (status 2), --help, --version
                code = stop.code if isinstance(stop.code, int) else 1
    finally:
        os.chdir(here)
    return subprocess.CompletedProcess(
        ["isoflow", *args], code, stdout=out.getvalue(), stderr=err.getvalue()
    )


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
