"""Thread counts: the limits in force inside the loop for every BLAS, the default policy,
requests and environment bounds, the nesting rule, the record in ``SolveStats`` and in files,
and the command line's flags.

The test suite pins BLAS to one thread at import (``conftest.py``), so what must be seen
against the libraries' own defaults (one thread per core) runs in a subprocess started with an
environment free of ``*_NUM_THREADS``.
"""

from __future__ import annotations

import atexit
import contextlib
import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import isoflow as iso
from isoflow import ParameterError
from isoflow.threads import available_cores, plan_threads

HERE = Path(__file__).resolve().parent
CORES = available_cores()
two_cores = pytest.mark.skipif(CORES < 2, reason="needs 2 cores (one core: one thread anyway)")

#: Environment variables that bound the thread counts (removed for the tests that need none).
BOUNDS = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OMP_NUM_THREADS", "NUMBA_NUM_THREADS")


def _clean_env() -> dict[str, str]:
    """This process's environment without thread bounds, with ``tests/`` importable."""
    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(HERE), env.get("PYTHONPATH")) if p)
    return env


@pytest.fixture
def unbounded(monkeypatch: pytest.MonkeyPatch) -> None:
    """No thread bounds from the environment for this test."""
    for name in BOUNDS:
        monkeypatch.delenv(name, raising=False)


def _blas_pools() -> list[tuple[str, int]]:
    """``(library, threads)`` of every loaded BLAS, sorted."""
    from threadpoolctl import threadpool_info

    return sorted(
        (os.path.basename(p["filepath"]), int(p["num_threads"]))
        for p in threadpool_info()
        if p["user_api"] == "blas"
    )


class _Recorder:
    """A stream writer that records the BLAS pools and numba's threads whenever the loop hands
    it rows (on the loop's thread: fewer rows than the writer thread needs)."""

    flush_seconds = math.inf

    def __init__(self, chunk_rows: int = 2) -> None:
        self.chunk_rows = chunk_rows
        self.seen: list[dict[str, Any]] = []

    def open(self, meta: dict[str, Any]) -> None:
        """Nothing to prepare."""

    def append(self, ts: Any, ys: Any, series: Any) -> None:
        import numba

        self.seen.append({"blas": _blas_pools(), "numba": numba.get_num_threads()})

    def checkpoint(self, step: int, y: Any, method_state: Any, failures: Any) -> None:
        """Nothing to keep."""

    def close(self, info: dict[str, Any]) -> None:
        """Nothing to release."""


_CALLS = [0]


def _importing_B(W: Any) -> Any:
    """A rigid body's ``B`` that imports SciPy's linear algebra (loading SciPy's own OpenBLAS)
    at its 30th call, in the middle of the run, unless something loaded it earlier (the
    compiled eigenvalues of the diagnostics do: numba loads SciPy's BLAS with its linear
    algebra)."""
    _CALLS[0] += 1
    if _CALLS[0] == 30:
        import scipy.linalg  # noqa: F401
    n = W.shape[-1]
    d = 1.0 + np.arange(n) / n
    return -0.5 * (d[:, None] + d[None, :]) * W


def _inside_the_loop(path: str) -> None:
    """Run in a fresh process without thread bounds: print what the loop saw (JSON).

    ``path`` is ``"compiled"`` (the BLAS stage: numba's ``np.dot`` into SciPy's cython BLAS,
    which nothing loaded before the run) or ``"numpy"`` (a Python ``B``; SciPy's BLAS loads
    during the run)."""
    from threadpoolctl import threadpool_limits

    import isoflow as iso

    out: dict[str, Any] = {"scipy_at_start": "scipy.linalg" in sys.modules}
    out["before"] = _blas_pools()
    if path == "numpy":
        alg = iso.algebras.so(4)
        rec = _Recorder()
        prob = iso.IsospectralProblem(algebra=alg, B=_importing_B)
        W0 = alg.random(seed=0, scale=0.5)
        iso.solve(prob, iso.IsoMP(), W0, dt=0.1, n_steps=20, writer=rec)
        out["seen"] = rec.seen
        out["after"] = _blas_pools()
        print(json.dumps(out))
        return
    prob, W0 = iso.models.rigid_body(20)
    for name, threads, outside in [
        ("default", None, None),
        ("blas 2", {"blas": 2, "numba": 1}, 1),
        ("limits block", "block", None),
    ]:
        rec = _Recorder()
        with threadpool_limits(outside) if outside else contextlib.nullcontext():
            if threads == "block":
                with iso.threads.thread_limits(blas=1, numba=1):
                    sol = iso.solve(prob, iso.IsoMP(), W0, dt=0.1, n_steps=8, writer=rec)
            else:
                sol = iso.solve(
                    prob, iso.IsoMP(), W0, dt=0.1, n_steps=8, writer=rec, threads=threads
                )
        out[name] = {"seen": rec.seen, "stats": sol.stats.threads, "runner": sol.stats.runner}
    print(json.dumps(out))


def _children(*args: str) -> list[dict[str, Any]]:
    """``_inside_the_loop(arg)`` for each argument, in fresh processes side by side."""
    procs = []
    for arg in args:
        code = f"import sys; sys.path.insert(0, {str(HERE)!r}); import test_threads as t; "
        code += f"t._inside_the_loop({arg!r})"
        pipe = subprocess.PIPE
        proc = subprocess.Popen(
            [sys.executable, "-c", code], env=_clean_env(), stdout=pipe, stderr=pipe, text=True
        )
        procs.append(proc)
    outs = []
    for proc in procs:
        stdout, stderr = proc.communicate(timeout=300)
        assert proc.returncode == 0, stderr
        outs.append(json.loads(stdout.strip().splitlines()[-1]))
    return outs


def _counts(record: dict[str, Any]) -> list[int]:
    return [t for _, t in record["blas"]]


@two_cores
def test_limits_hold_inside_the_loop_for_numpys_and_scipys_openblas() -> None:
    compiled, numpy_path = _children("compiled", "numpy")
    for out in (compiled, numpy_path):
        # only NumPy's OpenBLAS is loaded, with its own default, which the loop must override
        assert not out["scipy_at_start"] and [t for _, t in out["before"]] == [CORES]
    # the compiled BLAS stage: both OpenBLAS builds at the plan's count from the first row on
    for name, blas, numba in [("default", 1, CORES), ("blas 2", 2, 1), ("limits block", 1, 1)]:
        run = compiled[name]
        assert run["runner"] == "compiled, dense so(20) (BLAS)"
        assert run["stats"] == {"cores": CORES, "blas": blas, "numba": 1}, name
        assert len(run["seen"]) >= 4
        for s in run["seen"]:
            assert len(s["blas"]) == 2 and set(_counts(s)) == {blas}, (name, s)
            assert s["numba"] == numba, (name, s)
    # the NumPy path: SciPy's OpenBLAS, loaded during the run, limited from the next chunk on
    seen = numpy_path["seen"]
    first = next(i for i, s in enumerate(seen) if len(s["blas"]) == 2)
    assert len(seen[-1]["blas"]) == 2 and first < len(seen) - 2, seen
    for s in seen[:first] + seen[first + 1 :]:
        assert _counts(s) == [1] * len(s["blas"]), seen
    assert _counts({"blas": numpy_path["after"]}) == [CORES, CORES]  # restored after the run


def test_limits_changed_during_a_run_are_applied_again_from_the_next_chunk() -> None:
    from threadpoolctl import threadpool_limits

    calls = [0]

    def B(W: Any) -> Any:  # resets the BLAS threads to 2 in the middle of the run
        calls[0] += 1
        if calls[0] == 30:
            threadpool_limits(2)  # (as another thread's solve restoring its limits would)
        return -0.5 * W * np.arange(1, 5)[:, None] * np.arange(1, 5)[None, :]

    alg = iso.algebras.so(4)
    rec = _Recorder()
    prob = iso.IsospectralProblem(algebra=alg, B=B)
    iso.solve(prob, iso.IsoMP(), alg.random(seed=0, scale=0.5), dt=0.1, n_steps=20, writer=rec)
    reset = [i for i, s in enumerate(rec.seen) if 2 in _counts(s)]
    assert len(reset) == 1, rec.seen  # the next chunk limits it again
    assert all(_counts(s) == [1] * len(s["blas"]) for s in rec.seen[-3:]), rec.seen


# ---- the policy and requests --------------------------------------------------------------------


def test_default_is_one_blas_thread_and_numba_on_every_core(unbounded: None) -> None:
    import numba

    plan = plan_threads()
    assert (plan.blas, plan.numba, plan.cores) == (
        1,
        min(CORES, numba.config.NUMBA_NUM_THREADS),
        CORES,
    )


@pytest.mark.parametrize(
    ("threads", "message"),
    [
        (0, "threads must be a positive integer, got 0"),
        (True, "threads must be None, a number of cores or {'blas': b, 'numba': m}, got True"),
        (1.5, "threads must be None, a number of cores or {'blas': b, 'numba': m}, got 1.5"),
        ("2", "threads must be None, a number of cores or {'blas': b, 'numba': m}, got '2'"),
        ({"blas": 0}, "threads['blas'] must be a positive integer, got 0"),
        ({"numba": 1.0}, "threads['numba'] must be a positive integer, got 1.0"),
        ({"cpu": 1}, "threads: unknown key(s) cpu; give 'blas' and/or 'numba'"),
        (
            CORES + 1,
            f"threads = {CORES + 1} exceeds the {CORES} core(s) this process may run on; give "
            f"at most {CORES}",
        ),
        (
            {"blas": 2, "numba": CORES},
            f"threads: blas * numba = 2 * {CORES} exceeds the {CORES} available core(s); "
            "nested pools would oversubscribe them",
        ),
    ],
)
def test_bad_thread_requests_are_refused_before_the_run(threads: Any, message: str) -> None:
    prob, W0 = iso.models.rigid_body(4)
    with pytest.raises(ParameterError) as err:
        iso.solve(prob, iso.IsoMP(), W0, dt=0.1, n_steps=2, threads=threads)
    assert str(err.value) == message


def test_a_malformed_environment_bound_is_named(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("OMP_NUM_THREADS", "two")
    with pytest.raises(ParameterError) as err:
        plan_threads()
    assert str(err.value) == (
        "OMP_NUM_THREADS='two' is not a positive thread count; set it to an integer >= 1 or "
        "unset it"
    )
    monkeypatch.setenv("OMP_NUM_THREADS", "")  # set but empty: no bound
    assert plan_threads(1).blas == 1


def _with_numba_threads(count: str, *args: str) -> subprocess.CompletedProcess[str]:
    """``python *args`` in a process of its own with ``NUMBA_NUM_THREADS=count`` (numba reads
    it when it starts, once per process)."""
    env = {**_clean_env(), "NUMBA_NUM_THREADS": count}
    return subprocess.run([sys.executable, *args], env=env, capture_output=True, text=True,
                          timeout=600, check=False)  # fmt: skip


def test_a_malformed_numba_thread_count_is_named_before_numba_refuses_it() -> None:
    """numba's own import fails on NUMBA_NUM_THREADS=0 ("must be > 0", naming nothing): the
    models, the solve and the command line name the variable first, in one line."""
    message = (
        "NUMBA_NUM_THREADS='0' is not a positive thread count; set it to an integer >= 1 or "
        "unset it"
    )
    code = (
        "import isoflow as iso\n"
        "try:\n"
        "    iso.models.rigid_body(4)\n"
        "except iso.ParameterError as exc:\n"
        "    print(exc)\n"
        "alg = iso.algebras.so(3)\n"
        "prob = iso.IsospectralProblem(B=lambda W: -W, algebra=alg)\n"
        "try:\n"
        "    iso.solve(prob, iso.IsoMP(), alg.random(0), dt=0.1, n_steps=2)\n"
        "except iso.ParameterError as exc:\n"
        "    print(exc)\n"
    )
    out = _with_numba_threads("0", "-c", code)
    assert out.returncode == 0 and out.stdout.splitlines() == [message] * 2, out.stderr[-2000:]
    cli = _with_numba_threads("0", "-m", "isoflow.cli", "run", "rigid-body", "--n-steps", "2")
    assert cli.returncode == 1 and cli.stderr.strip() == f"isoflow: error: {message}"


@two_cores
def test_environment_variables_bound_every_request(
    unbounded: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    assert plan_threads(2, parallel=False).blas == 2
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "1")
    assert plan_threads(2, parallel=False).blas == 1
    assert plan_threads({"blas": 2, "numba": 1}).blas == 1
    monkeypatch.delenv("OPENBLAS_NUM_THREADS")
    monkeypatch.setenv("OMP_NUM_THREADS", "1,1")  # OpenMP's per-level list: the first counts
    assert plan_threads(2, parallel=False).blas == 1
    monkeypatch.delenv("OMP_NUM_THREADS")
    # numba's own bound, in a run: an ensemble would otherwise run its members on 2 threads.
    # In a process of its own: numba reads NUMBA_NUM_THREADS when it starts its pool, and a
    # pool already running in this process (from an earlier test) cannot be changed.
    code = (
        "import json, isoflow as iso\n"
        "prob, _ = iso.models.rigid_body(4)\n"
        "W = iso.algebras.so(4).random(seed=0, batch=(64,), scale=0.1)\n"
        "s = iso.solve(prob, iso.IsoMP(), W, dt=0.1, n_steps=2, threads=2).stats\n"
        "print(json.dumps([s.runner, s.threads]))\n"
    )
    out = _with_numba_threads("1", "-c", code)
    assert out.returncode == 0, out.stderr[-2000:]
    runner, threads = json.loads(out.stdout.strip().splitlines()[-1])
    assert "SIMD lanes" in runner  # serial: the 2 cores went to BLAS
    assert threads == {"cores": CORES, "numba": 1, "blas": 2}


@two_cores
def test_a_number_of_cores_goes_to_the_pool_the_run_uses(unbounded: None) -> None:
    W = iso.algebras.so(4).random(seed=0, batch=(64,), scale=0.1)
    prob, W0 = iso.models.rigid_body(4)
    ensemble = iso.solve(prob, iso.IsoMP(), W, dt=0.1, n_steps=2, threads=2).stats
    assert "SIMD lanes" in ensemble.runner
    assert ensemble.threads == {"cores": CORES, "numba": 2, "blas": 1}
    single = iso.solve(prob, iso.IsoMP(), W0, dt=0.1, n_steps=2, threads=2).stats
    assert single.threads == {"cores": CORES, "numba": 1, "blas": 2}
    serial = iso.solve(prob, iso.IsoMP(), W, dt=0.1, n_steps=2, threads=1).stats
    assert serial.threads == {"cores": CORES, "numba": 1, "blas": 1}


@two_cores
def test_compiled_members_calling_blas_run_serially_under_blas_threads(
    unbounded: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    # 4 cores pretended, so that 2 BLAS x 2 numba threads is a valid request on this machine
    monkeypatch.setattr(iso.threads, "available_cores", lambda: 4)
    prob, _ = iso.models.rigid_body(20)
    W = iso.algebras.so(20).random(seed=0, batch=(4,), scale=0.1)
    stats = iso.solve(prob, iso.IsoMP(), W, dt=0.1, n_steps=2, threads={"blas": 2, "numba": 2})
    assert stats.stats.runner == "compiled, dense so(20) (BLAS)"
    assert stats.stats.threads == {"cores": 4, "numba": 1, "blas": 2}
    stats = iso.solve(prob, iso.IsoMP(), W, dt=0.1, n_steps=2, threads={"blas": 1, "numba": 2})
    assert stats.stats.threads == {"cores": 4, "numba": 2, "blas": 1}


# ---- the record ---------------------------------------------------------------------------------


def test_the_threads_used_are_in_the_stats_the_file_and_isoflow_info(
    unbounded: None, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import numba

    from isoflow import cli

    numba_threads = min(CORES, numba.config.NUMBA_NUM_THREADS)
    prob, _ = iso.models.rigid_body(4)
    W = iso.algebras.so(4).random(seed=0, batch=(64,), scale=0.1)
    path = tmp_path / "run.h5"
    sol = iso.solve(prob, iso.IsoMP(), W, dt=0.1, n_steps=4, writer=iso.io.HDF5Writer(path))
    expected = {"cores": CORES, "numba": numba_threads, "blas": 1}
    assert sol.stats.threads == expected
    assert iso.io.info(path)["run_info"]["stats"]["threads"] == expected
    assert cli.main(["info", str(path)]) == 0
    line = rf"  threads +1 BLAS, {numba_threads} numba \({CORES} cores\)"
    assert re.search(line, capsys.readouterr().out)


# ---- the command line ---------------------------------------------------------------------------


#: What the probe model's ``B`` saw: the BLAS pools at every call.
PROBE: list[list[tuple[str, int]]] = []


def probe_model(n: int = 4):
    """A rigid body whose Python ``B`` records the BLAS pools at every call (in :data:`PROBE`,
    and written to ``$ISOFLOW_THREADS_PROBE`` as JSON when the process ends, if set)."""
    PROBE.clear()
    if os.environ.get("ISOFLOW_THREADS_PROBE"):
        out = Path(os.environ["ISOFLOW_THREADS_PROBE"])
        atexit.register(lambda: out.write_text(json.dumps(PROBE)))
    d = 1.0 + np.arange(n) / n
    C = 0.5 * (d[:, None] + d[None, :])

    def B(W: Any) -> Any:
        PROBE.append(_blas_pools())
        return -C * W

    alg = iso.algebras.so(n)
    return iso.IsospectralProblem(algebra=alg, B=B), alg.random(seed=0, scale=0.5)


PROBE_RUN = ["--model", "test_threads:probe_model", "--dt", "0.1", "--n-steps", "30", "--quiet"]


@two_cores
def test_the_command_lines_default_takes_effect_against_the_libraries_default(
    tmp_path: Path,
) -> None:
    from cli_helpers import run_cli

    env = {**_clean_env(), "ISOFLOW_THREADS_PROBE": str(tmp_path / "probe.json")}
    res = run_cli("run", *PROBE_RUN, "--out", "run.h5", cwd=tmp_path, env=env)
    assert res.returncode == 0, res.stderr
    records = json.loads((tmp_path / "probe.json").read_text())
    assert len(records) > 20 and all(t == 1 for r in records for _, t in r), records
    assert re.search(rf"  threads +1 BLAS, 1 numba \({CORES} cores\)", res.stdout)


@two_cores
@pytest.mark.parametrize(
    "where",
    [["run", "--threads", "2"], ["run", "--blas-threads", "2"], ["--blas-threads", "2", "run"]],
)
def test_the_thread_flags_take_effect_inside_the_loop(
    unbounded: None, tmp_path: Path, capsys: pytest.CaptureFixture[str], where: list[str]
) -> None:
    from isoflow import cli

    out = tmp_path / "run.h5"
    assert cli.main([*where, *PROBE_RUN, "--out", str(out)]) == 0  # the suite pins BLAS to 1
    in_loop = PROBE[-40:]  # of about 80 calls; the first one checks B before the run
    assert len(PROBE) > 60 and all(t == 2 for r in in_loop for _, t in r), PROBE
    expected = {"cores": CORES, "numba": 1, "blas": 2}
    assert iso.io.info(out)["run_info"]["stats"]["threads"] == expected
    assert re.search(rf"  threads +2 BLAS, 1 numba \({CORES} cores\)", capsys.readouterr().out)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--threads", "1", "--blas-threads", "1"], "give --threads or --blas-threads, not both"),
        (
            ["--threads", str(CORES + 1)],
            f"threads = {CORES + 1} exceeds the {CORES} core(s) this process may run on; give "
            f"at most {CORES}",
        ),
    ],
)
def test_bad_thread_flags_get_one_line(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    from isoflow import cli

    assert cli.main(["run", "rigid-body", "--n-steps", "2", "--dt", "0.1", *argv]) == 1
    assert capsys.readouterr().err == f"isoflow: error: {message}\n"


def test_resume_refuses_a_bad_request_before_touching_the_file(tmp_path: Path) -> None:
    prob, W0 = iso.models.rigid_body(4)
    path = tmp_path / "run.h5"
    iso.solve(prob, iso.IsoMP(), W0, dt=0.1, n_steps=4, writer=iso.io.HDF5Writer(path))
    before = path.read_bytes()
    with pytest.raises(ParameterError, match="threads must be a positive integer, got 0"):
        iso.io.resume(path, problem=prob, method=iso.IsoMP(), threads=0)
    assert path.read_bytes() == before
