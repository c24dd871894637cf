"""The benchmark suite's registry and shared tools: timing, runners, the machine, the report.

Every benchmark is a function ``run(quick: bool) -> list[dict]`` in a file
``bench_<k>_<name>.py`` of this directory, registered under its number with
:func:`benchmark`::

    from suite import benchmark

    @benchmark(8, "so(10) rigid body through CompiledB against the built-in kernel")
    def run(quick: bool) -> list[dict]:
        ...
        return [record(8, "what was measured", metric="speed-up (...)", value=..., target=">= 6",
                       met=...)]

:func:`load` imports every ``bench_*.py`` file (so adding a benchmark is adding a file) and
:data:`BENCHMARKS` then maps numbers to benchmarks. Each benchmark times its own baseline in the
same process (alternately, best of the repeats) and reports a ratio, so the numbers transfer
between machines; numba compilation is excluded (every path runs once first).

The compiled time loops are reached the way :func:`isoflow.solve` reaches them:
:func:`isoflow._compiled.compiled_runner` and, for the NumPy path, the method's own steps
(:class:`isoflow._stepping.PythonRunner`) on the same problem without its kernel.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib.util
import math
import platform
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from isoflow._save_grid import SaveGrid

HERE = Path(__file__).resolve().parent

__all__ = [
    "BENCHMARKS",
    "Benchmark",
    "StepTimer",
    "benchmark",
    "best_time",
    "load",
    "machine",
    "paired_best_times",
    "record",
    "to_markdown",
]


@dataclass(frozen=True)
class Benchmark:
    """A numbered benchmark: ``run(quick) -> list of records`` (see :func:`record`)."""

    number: int
    title: str
    run: Callable[[bool], list[dict[str, Any]]]
    source: str
    figure: Callable[[list[dict[str, Any]], Path], None] | None = None


#: number -> benchmark, filled by :func:`load`.
BENCHMARKS: dict[int, Benchmark] = {}


def benchmark(
    number: int, title: str, *, figure: Callable[[list[dict[str, Any]], Path], None] | None = None
) -> Callable[[Callable[[bool], Any]], Callable[[bool], Any]]:
    """Register the decorated ``run(quick)`` as benchmark ``number``.

    ``figure(records, path)``, if given, draws the benchmark's records into a PNG file
    (``run_all.py --figure PATH``).
    """

    def register(func: Callable[[bool], Any]) -> Callable[[bool], Any]:
        if func.__module__ == "__main__":
            return func  # a bench file run as a script: run_all loads it as a module
        old = BENCHMARKS.get(number)
        if old is not None and old.source != func.__module__:
            raise RuntimeError(
                f"benchmark {number} is defined twice ({old.source}, {func.__module__})"
            )
        BENCHMARKS[number] = Benchmark(number, title, func, func.__module__, figure)
        return func

    return register


#: Modules holding several benchmarks in a ``BENCHMARKS`` dict (number -> ``run(quick)``),
#: their titles in the module docstring's numbered list (``8.  what against what``).
GROUPED = ("design",)


def _import(name: str, path: Path) -> Any:
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, path)
        assert spec is not None and spec.loader is not None
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return sys.modules[name]


def _numbered_titles(doc: str, width: int = 90) -> dict[int, str]:
    """``{k: title}`` from the paragraphs ``k.  ...`` of a docstring (cut to ``width``)."""
    paragraphs: dict[int, list[str]] = {}
    current: list[str] | None = None
    for line in doc.splitlines():
        head, dot, rest = line.partition(".")
        if dot and head.strip().isdigit() and rest.startswith(" "):
            current = paragraphs.setdefault(int(head), [])
            current.append(rest.strip())
        elif current is not None and line.startswith("    ") and line.strip():
            current.append(line.strip())
        else:
            current = None
    titles = {}
    for k, words in paragraphs.items():
        text = " ".join(words).replace("``", "")
        if len(text) > width:
            text = text[: width - 1].rsplit(" ", 1)[0] + " ..."
        titles[k] = text
    return titles


def load() -> dict[int, Benchmark]:
    """Import every ``bench_*.py`` of this directory and the grouped modules; returns
    :data:`BENCHMARKS` sorted by number."""
    if str(HERE) not in sys.path:
        sys.path.insert(0, str(HERE))
    for path in sorted(HERE.glob("bench_*.py")):
        _import(path.stem, path)
    for name in GROUPED:
        path = HERE / f"{name}.py"
        if not path.is_file():
            continue
        module = _import(name, path)
        titles = _numbered_titles(module.__doc__ or "")
        for number, run in module.BENCHMARKS.items():
            benchmark(number, titles.get(number, f"benchmark {number}"))(run)
    return dict(sorted(BENCHMARKS.items()))


def record(
    number: int, name: str, *, metric: str, value: float, target: str, met: bool | None,
    **numbers: Any,
) -> dict[str, Any]:  # fmt: skip
    """One row of the report: what was measured, the ratio, its target and whether it is met."""
    return {"id": number, "name": name, **numbers, "metric": metric, "value": value,
            "target": target, "met": met}  # fmt: skip


# ---- timing ------------------------------------------------------------------------------------


def two_products(B: Any, X: Any, P: Any, T: Any) -> None:
    """``P = B X`` and ``T = P B`` through numba's ``np.dot``: the BLAS library (SciPy's
    OpenBLAS) that the compiled paths call.

    A baseline through ``numpy.matmul`` would use NumPy's own OpenBLAS, a second library with
    its own threads: alternated with the compiled path, each library's threads spin on the
    cores after their calls and slow the other's (measured on 2 cores: 1024 x 1024 products
    in 37 ms instead of 23 ms with two threads).
    """
    _two_products_compiled()(B, X, P, T)


@functools.cache
def _two_products_compiled() -> Any:
    import numba

    @numba.njit(cache=True)
    def products(B, X, P, T):  # type: ignore[no-untyped-def]
        np.dot(B, X, P)
        np.dot(P, B, T)

    return products


def combining_pass_seconds(alg: Any, X: Any, P: Any) -> float:
    """Best time of the compiled loop's pass after the two products (:func:`isoflow._compiled.
    dense_tiles._combine`: bracket, next iterate, residual, mirrored into ``V``), on one thread;
    repeated inside a compiled loop (about 2e6 entries a call) so that small ``n`` is not
    timed with a Python call's overhead."""
    from isoflow._compiled import dense

    n = alg.shape[0]
    _, rowoff = dense.packed_row_offsets(n)
    Tp = np.zeros(n * n, dtype=X.dtype)
    G = np.empty_like(X)
    s = -1.0  # both spaces are skew
    reps = max(1, int(2e6 / n**2))
    loop = _combine_loop()
    loop(X, X, P, Tp, rowoff, G, s, 1)
    best = np.inf
    for _ in range(5):
        t = time.perf_counter()
        loop(X, X, P, Tp, rowoff, G, s, reps)
        best = min(best, time.perf_counter() - t)
    return float(best / reps)


@functools.cache
def _combine_loop() -> Any:
    import numba

    from isoflow._compiled import dense_tiles

    combine = dense_tiles._combine

    @numba.njit
    def loop(W, X, P, Tp, rowoff, G, s, reps):  # type: ignore[no-untyped-def]
        for _ in range(reps):
            combine(W, X, P, Tp, rowoff, G, s, 0.05, 0.0025)

    return loop


def best_time(fn: Callable[[], Any], repeats: int = 5, min_time: float = 0.0) -> float:
    """Best (smallest) wall time of ``fn()`` over ``repeats`` runs, after one warm-up run.

    The minimum: on a shared machine other load only ever adds time. With ``min_time``, stop
    after at least three runs once their total exceeds it.
    """
    fn()
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
        if min_time and sum(times) > min_time and len(times) >= 3:
            break
    return min(times)


def paired_best_times(
    fa: Callable[[], Any], fb: Callable[[], Any], repeats: int = 5
) -> tuple[float, float]:
    """Best times of ``fa()`` and ``fb()``, timed alternately (after one warm-up each).

    Alternating the two keeps their ratio fair when other load on the machine comes and goes.
    """
    fa()
    fb()
    ta, tb = [], []
    for _ in range(repeats):
        t = time.perf_counter()
        fa()
        ta.append(time.perf_counter() - t)
        t = time.perf_counter()
        fb()
        tb.append(time.perf_counter() - t)
    return min(ta), min(tb)


class StepTimer:
    """Steps of one run taken by the compiled loop or by the NumPy path, chunk after chunk.

    Parameters
    ----------
    problem, method, y, h :
        The run (``y`` a single state or an ensemble).
    compiled : bool
        The compiled runner (an error if the run has none) or the method's own NumPy steps on
        the same problem without its kernel.

    :meth:`advance` continues from where the last call stopped, saving no state, so
    a benchmark times stepping alone. It runs with the thread counts a solve of the same run
    would (the enclosing :func:`isoflow.threads.thread_limits` block's, else the default: one
    BLAS thread), applied to every BLAS library as a solve applies them; without them, SciPy's
    OpenBLAS (the one the compiled dense loops call) kept its default of one thread per core.
    """

    def __init__(self, problem: Any, method: Any, y: Any, h: float, *, compiled: bool = True):
        from isoflow._compiled import compiled_runner
        from isoflow._stepping import PythonRunner

        y = np.asarray(y, dtype=problem.algebra.dtype)
        method = method.for_problem(problem)  # the method a solve of the run steps with
        if compiled:
            runner = compiled_runner(problem, method, y, h)
            if runner is None:
                raise RuntimeError(f"no compiled path for {method.name} on {problem.algebra.name}")
        else:
            runner = PythonRunner(dataclasses.replace(problem, kernel=None), method, y, h)
        self.runner = runner
        self.dtype = problem.algebra.dtype
        self.label = runner.label

    def advance(self, n: int) -> int:
        """Take ``n`` steps; returns the nonlinear iterations they took (all members)."""
        from isoflow.threads import ThreadPools, plan_threads

        r = self.runner
        before = r.iterations_total
        out = np.empty((1, r.M, *r.core), dtype=self.dtype)
        pools = ThreadPools()
        try:
            pools.apply(plan_threads(None, parallel=r.parallel))
            # the steps of a long run between two save points (a chunk's step data drawn
            # ahead goes on to the next call's first steps, as from chunk to chunk of a run)
            r.advance(n, SaveGrid(2**62, 2**62), out)
        finally:
            pools.restore()
        if not r.failures.alive.all():
            m = int(r.failures.failed[0])
            raise RuntimeError(f"a benchmark run failed ({r.label}): {r.failures.reason(m)}")
        return int(r.iterations_total - before)

    def state(self) -> Any:
        """The current state."""
        return self.runner.state()[0]


# ---- report ------------------------------------------------------------------------------------


def machine() -> dict[str, Any]:
    """Description of the machine and the thread pools."""
    import numba

    from isoflow.threads import current_threads

    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:  # pragma: no cover
        pass
    blas = "unknown"
    try:
        from threadpoolctl import threadpool_info

        info = [p for p in threadpool_info() if p.get("user_api") == "blas"]
        if info:
            blas = f"{info[0].get('internal_api')} {info[0].get('version')}"
    except Exception:  # pragma: no cover
        pass
    th = current_threads()
    return {
        "cpu": cpu,
        "cores": th["cores"],
        "python": platform.python_version(),
        "numpy": np.__version__,
        "numba": numba.__version__,
        "blas": blas,
        "numba_threads": th["numba"],
        "blas_threads": th["blas"],
    }


def _fmt(v: Any) -> str:
    if isinstance(v, bool) or v is None:
        return {True: "yes", False: "**no**", None: "-"}[v]
    if isinstance(v, float):
        return f"{v:.3g}"
    return str(v)


def to_markdown(report: dict[str, Any]) -> str:
    """The results as a markdown table (one row per measurement) with the machine line."""
    m = report["machine"]
    lines = [
        f"Machine: {m['cpu']}, {m['cores']} cores, {m['blas']}, numpy {m['numpy']}, "
        f"numba {m['numba']}, Python {m['python']}; total {report['wall_time']:.0f} s.",
        "",
        "| # | benchmark | measured | target | met |",
        "|---|---|---|---|---|",
    ]
    for r in report["results"]:
        lines.append(
            f"| {r['id']} | {r['name']} | {r['metric'].split(' (')[0]} {_fmt(r['value'])} | "
            f"{r['target']} | {_fmt(r['met'])} |"
        )
    return "\n".join(lines) + "\n"


def jsonable(x: Any) -> Any:
    """``x`` with NumPy scalars as Python numbers and non-finite floats as strings."""
    if isinstance(x, dict):
        return {k: jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [jsonable(v) for v in x]
    if isinstance(x, np.floating | np.integer):
        x = x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return str(x)
    return x
