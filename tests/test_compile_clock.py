"""What a run says about compiling, and how much of its time it counts as compiling.

A run times everything numba does to get machine code (``SolveStats.compile_time``: the user's
function, the wrapper that calls it from Python, the compiled loops) and announces every
compilation on stderr, from Python as from the command line; loading from numba's cache is
counted but not announced.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import uuid
from pathlib import Path
from typing import Any

import numba
import numpy as np
import pytest

import isoflow as iso

N = 5
_D = 1.0 / np.arange(1, N + 1)
COEFF = 0.5 * (_D[:, None] + _D[None, :])

#: A user's module with a kernel function of a name (and so a source) never compiled before.
KERNEL_MODULE = """
import numba


@numba.njit(cache=True)
def {name}(W, out, C):
    n = W.shape[0]
    for i in range(n):
        for j in range(n):
            out[i, j] = -C[i, j] * W[i, j]
"""

#: Solve with that kernel in a new process; print the first call's wall time and statistics.
SOLVE_SCRIPT = """
import importlib, json, sys, time
import numpy as np
import isoflow as iso

f = getattr(importlib.import_module(sys.argv[1]), sys.argv[2])
n = {n}
d = 1.0 / np.arange(1, n + 1)
C = 0.5 * (d[:, None] + d[None, :])
alg = iso.algebras.so(n)
prob = iso.IsospectralProblem(algebra=alg, kernel=iso.CompiledB(f, (C,)))
start = time.perf_counter()
sol = iso.solve(prob, iso.IsoMP(), alg.random(0), dt=0.1, n_steps=20)
wall = time.perf_counter() - start
import numba
start = time.perf_counter()
numba.njit(f.py_func).compile(f.signatures[0])  # the user's function alone, compiled again
user = time.perf_counter() - start
print(json.dumps({{"wall": wall, "user": user, "compile_time": sol.stats.compile_time,
                  "wall_time": sol.stats.wall_time, "runner": sol.stats.runner,
                  "cache": f._cache._cache_path}}))
"""


def _solve_in_new_process(directory: Path, name: str) -> tuple[dict[str, Any], str]:
    env = dict(os.environ, PYTHONPATH=str(directory), OPENBLAS_NUM_THREADS="1")
    res = subprocess.run(
        [sys.executable, "-c", SOLVE_SCRIPT.format(n=N), f"kernel_{name}", name],
        capture_output=True, text=True, timeout=600, check=False, cwd=directory, env=env,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout.strip().splitlines()[-1]), res.stderr


def test_a_new_kernel_is_announced_on_stderr_and_counted_then_loaded_silently(
    tmp_path: Path, request: pytest.FixtureRequest
) -> None:
    name = f"user_field_{uuid.uuid4().hex[:12]}"
    (tmp_path / f"kernel_{name}.py").write_text(KERNEL_MODULE.format(name=name))

    first, err = _solve_in_new_process(tmp_path, name)
    request.addfinalizer(lambda: shutil.rmtree(first["cache"], ignore_errors=True))
    assert first["runner"].startswith("compiled"), first
    assert f"isoflow: compiling {name} (first use of this code here;" in err, err
    assert f"isoflow: compiled {name} in " in err, err
    # compiling the user's function (in the validation of B, before the loop) is counted, with
    # the loops' compilation or loading on top
    assert first["compile_time"] > 0.8 * first["user"], first
    assert first["compile_time"] <= first["wall_time"] <= first["wall"], first

    again, err = _solve_in_new_process(tmp_path, name)  # numba's cache has it now
    assert "compiling" not in err, err
    assert 0.0 < again["compile_time"] <= again["wall_time"], again


def _fresh_kernel() -> iso.CompiledB:
    """A function numba has not compiled in this process (no cache: a new one every call)."""

    @numba.njit
    def fresh_field(W, out, C):  # type: ignore[no-untyped-def]
        out[:, :] = -C * W

    return iso.CompiledB(fresh_field, (COEFF,))


@pytest.mark.parametrize("progress", [None, False])
def test_the_notice_comes_from_python_too_unless_progress_is_off(
    progress: bool | None, capsys: pytest.CaptureFixture[str]
) -> None:
    alg = iso.algebras.so(N)
    prob = iso.IsospectralProblem(algebra=alg, kernel=_fresh_kernel())
    sol = iso.solve(prob, iso.IsoMP(), alg.random(1), dt=0.1, n_steps=5, progress=progress)
    err = capsys.readouterr().err
    if progress is None:
        assert "isoflow: compiling fresh_field (first use of this code here;" in err, err
        assert "isoflow: compiled fresh_field in " in err, err
    else:
        assert err == ""
    assert 0.0 < sol.stats.compile_time <= sol.stats.wall_time

    again = iso.solve(prob, iso.IsoMP(), alg.random(1), dt=0.1, n_steps=5, progress=progress)
    assert capsys.readouterr().err == ""  # compiled in this process already: nothing to say
    assert again.stats.compile_time < 0.05 and again.y_final.tobytes() == sol.y_final.tobytes()


def test_the_command_line_announces_also_with_quiet(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from isoflow import _compile_clock

    monkeypatch.setattr(_compile_clock, "SHOW", True)  # what the command line sets
    alg = iso.algebras.so(N)
    prob = iso.IsospectralProblem(algebra=alg, kernel=_fresh_kernel())
    iso.solve(prob, iso.IsoMP(), alg.random(1), dt=0.1, n_steps=5, progress=False)
    assert "isoflow: compiling fresh_field" in capsys.readouterr().err


def test_the_command_line_announces_while_its_command_runs(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    from isoflow import _compile_clock, _solve, cli

    seen: list[tuple[bool, bool]] = []
    clock = _solve.compile_clock

    def spy(show: bool):  # type: ignore[no-untyped-def]
        seen.append((show, _compile_clock.SHOW))
        return clock(show)

    monkeypatch.setattr(_solve, "compile_clock", spy)
    args = ["run", "rigid-body", "--n", "3", "--dt", "0.1", "--n-steps", "2", "--quiet"]
    assert cli.main([*args, "--out", str(tmp_path / "r.h5")]) == 0
    assert seen == [(False, True)]  # --quiet: no progress bar, compilations still announced
    assert _compile_clock.SHOW is False  # and only while the command ran


def test_a_function_that_does_not_compile_is_not_reported_as_compiled(
    capsys: pytest.CaptureFixture[str],
) -> None:
    @numba.njit
    def broken_field(W, out, C):  # type: ignore[no-untyped-def]
        out[:, :] = -C * W + undefined_name  # type: ignore[name-defined]  # noqa: F821

    alg = iso.algebras.so(N)
    prob = iso.IsospectralProblem(algebra=alg, kernel=iso.CompiledB(broken_field, (COEFF,)))
    with pytest.raises(iso.InvalidBError, match="broken_field does not compile"):
        iso.solve(prob, iso.IsoMP(), alg.random(1), dt=0.1, n_steps=5)
    err = capsys.readouterr().err
    assert "isoflow: compiling broken_field" in err and "compiled broken_field in" not in err


def test_a_named_block_is_announced_once_however_many_functions_it_compiles(
    capsys: pytest.CaptureFixture[str],
) -> None:
    from isoflow._compile_clock import compile_clock, compile_notice

    @numba.njit
    def first(x):  # type: ignore[no-untyped-def]
        return x + 1

    @numba.njit
    def second(x):  # type: ignore[no-untyped-def]
        return x * 2

    with compile_clock(show=True) as clock, compile_notice("the compiled loop for a test"):
        assert first(1) == 2 and second(2) == 4
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 2, lines
    assert lines[0].startswith("isoflow: compiling the compiled loop for a test (first use")
    assert lines[1].startswith("isoflow: compiled the compiled loop for a test in ")
    assert clock.compiled == 1 and clock.seconds > 0
