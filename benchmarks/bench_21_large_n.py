"""Benchmark 21: Euler on the sphere at large N (issue 24): time per unit of simulated time
against an older commit, and the thread scaling of one iteration.

1. The ``euler-sphere`` random vorticity (``seed = 1``), ``h ||B||_2 = 0.3``, IsoMP with its
   defaults, ``STEPS`` steps at N = 512 and 1024 (quick: 10 steps at N = 256), one BLAS
   thread: the seconds per unit of simulated time of this checkout against those of the commit
   ``ISOFLOW_BASELINE_REV`` (default: the commit before issue 24), whose ``src`` is taken
   with ``git archive`` from the checkout's repository. Each variant runs in a fresh process
   (imports and numba's cache loads are not timed; one warm-up step is); the two alternate,
   ``REPEATS`` times, and the best of each is compared (six states saved: the Casimirs of a
   saved state cost eigenvalues, more than a step). Also recorded: the iterations per
   step, the largest relative energy error and the Casimir drift of both (target: time at
   most 0.5 of the old, Casimir drift at rounding, energy error no larger).
2. One iteration at N = 512 and 1024 (quick: 256) with two threads against one, both in this
   process, alternately (target: at least 1.7x faster with two): what ``threads=2`` runs (the
   planar stage's pieces on two numba threads, one BLAS thread each) against ``threads=1``; a
   step's time over its iterations (the row's value: chunks of ``CHUNK_STEPS`` steps after
   the first ``WARM_STEPS`` of the run, as a long run takes them; until 2026-11-28 the row
   timed single steps from the run's second, whose calls and many iterations read 1.60x at
   N = 512 in a probe where chunks of 8 steps after 16 read 1.92x), and, as
   ``iteration_alone``, the
   stage's ``iterate`` called by itself (``B(X)``, the products, the passes after them;
   without the start and the offsets); two BLAS threads and one numba thread (what
   ``threads=2`` ran before) recorded beside, timed after the others (an OpenBLAS thread spins
   on its core for a while after each call).

**Measured** (Intel Xeon host, idle, 2026-11-28 13:58-14:14 UTC, ``python
benchmarks/run_all.py --only 21``), after the fallback check of the fitted start came to stop
once its miss had surely passed the limit (``isoflow._compiled.dense_start``: the start 6.1
against 7.9 ms a step at N = 512 inside a run): part 1 **0.64 at N = 512 and 0.13 at
N = 1024 with one thread** (0.60 and 0.11 with two; 13.8 against 21.6 s per unit of
simulated time at N = 512, the old code's time moving between runs as much as the gain);
part 2 **1.93x and 1.83x** (the iteration alone 1.82x and 1.90x). What keeps N = 512 above
0.5 after the first steps: the start misses by about the tolerance, so most steps take two
iterations (``docs/user_guide/solvers.rst`` has the windows, degrees and tolerances tried).

**Measured** (Intel Xeon host, idle, 2026-11-28 11:24-11:39 UTC, ``python
benchmarks/run_all.py --only 21``), after the start of large dense states came to read the
lower triangle of the offsets (``isoflow._compiled.dense_start``; the same starts bit for
bit): part 1 **0.63 at N = 512 and 0.14 at N = 1024 with one thread** (0.63 and 0.11 with
two), 2.3 and 1.82 iterations a step against 4.28 and 3.32, the same energy error
(6.17e-6, 3.08e-6) and Casimir drift (1.7e-15, 1.2e-15) as the old code. Part 2 as it timed
until then (single steps from the run's second): 1.53x at N = 512 and 1.79x at N = 1024;
rerun at 11:41 UTC on chunks of steps 17-40 (``WARM_STEPS``, ``CHUNK_STEPS``): **1.87x and
1.80x** (35.7 against 19.1 ms a step's iteration at N = 512, 217 against 120 at 1024); the
iteration alone 1.85x and 1.90x.

**Measured** (Intel Xeon host, idle, 2026-11-28 08:08-08:37 UTC, ``python
benchmarks/run_all.py --only 13,21``), after the start of dense matrices from ``n = 512`` came
to fit 16 (from ``n = 1024``: 12) offsets by least squares (``docs/user_guide/solvers.rst``;
that run had the fit without the fallback to the interpolating start, which Euler's start
never takes, and which adds a pass of about 2.7 ms a step at N = 512: 0.68 in a rerun of part
1 at N = 512 at 09:10 UTC): part 1 **0.66 at N = 512 and 0.14 at N = 1024 with one thread**
(0.66 and 0.12 with two), 2.3 and 1.82 iterations a step against 4.28 and 3.32, the same
energy error (6.17e-6, 3.08e-6) and Casimir drift (1.7e-15, 1.2e-15) as the old code. What is
left at N = 512: the first steps, which have few offsets to fit (11, 8, 6, 5, 4, 3, 3
iterations, then 1-2: 40 of the 115 iterations), the six saved states' eigenvalues (the same
for both codes), and the start's sum over 16 offsets (about 8 ms a step, streamed from
memory). Part 2 read 1.47x and 1.49x in that run and 1.54-1.79x (N = 512) and 1.73x
(N = 1024) in three runs minutes later with nothing else changed (the host's other tenants):
with two iterations a step or fewer the step's serial work (the start, the finish) weighs on
each iteration more than with three.

Measured (Intel Xeon host, AVX-512, idle, 2026-11-28 03:23-03:47 UTC, ``python
benchmarks/run_all.py --only 12,21``), after the pieces went to numba threads and the dense
stages came to flush subnormal numbers (:mod:`isoflow._compiled.subnormals`): part 1 **0.76
at N = 512 and 0.17 at N = 1024 with one thread** (0.70 and 0.13 with two, against the old
code's two BLAS threads); the same energy error (6.17e-6, 3.08e-6) and Casimir drift
(1.3e-15, 1.2e-15) as the old code. At N = 1024 the experiment's vorticity leaves a fifth of
the entries below 1e-150 after a few steps, and the old code computed their subnormal
products in microcode (1052 against 176 s per unit of simulated time). At N = 512 the tails
stay normal, and the iteration is not cheaper than the old complex one on this host
(benchmark 12: 3M planar / complex tiles 1.01; zgemm is 3.6 dgemm here): what is left is the
iterations, 3.12 against 4.28 a step. Part 2 **met**: 1.80x and 1.87x a step's iteration at
N = 512 and 1024 (the iteration alone 1.83x and 1.91x; two BLAS threads 1.27x and 0.38x a
step, 1.55x and 1.68x the iteration alone, which starts from the state without tails: the
OpenBLAS threads do not flush subnormals, only the calling thread does).

The runs below were on an AMD EPYC host (zgemm about 3.4-3.7 dgemm there, 3M planar /
complex tiles 0.77-0.87).

Run alone: ``python benchmarks/bench_21_large_n.py``. Without git or the baseline commit,
part 1 is reported as not measured.

Measured on the idle machine, 2026-11-27 02:17-02:21 UTC (``python benchmarks/run_all.py
--only 21``), after the compiled loop stopped allocating its state-sized buffers in every
call (a solve at N = 1024 calls it every step or two, and 150 MB of fresh buffers cost 60-100
ms of page faults a call) and the sphere's field stopped the per-call copy kept for fields
that raise: **0.58 at N = 512 and 0.58 at N = 1024** (3.10 and 2.42 iterations a step against
4.28 and 3.32; the same energy error, 6.2e-6 and 3.1e-6, and Casimir drift, 1.1e-15 and
1.5e-15, as the old code); part 2 1.57x and 1.69x a step's iteration (the iteration alone
1.64x and 1.77x). What stands between 0.58 and 0.5 is the start of the run: the first steps
have too few stage offsets to extrapolate (at N = 1024 the first five take 11, 7, 6, 4 and 3
iterations, then 2 a step to the end; at N = 512 11, 8, 6, 5, 4, 3, 3, then 2-3), 21 of the
121 iterations at N = 1024. With those at the steady two, the ratio would be about 0.49;
Anderson mixing in these steps saved three iterations of the first one only (memory 1-3,
N = 512), and a run of 10^5 steps does not see them.

Tried and rejected (2026-11-27, 23:50 UTC, side by side against ``69a23e6``, one run each, a
host slower than usual): lagging the triple product by one iterate (iteration ``k >= 2``
combines ``P(X_k)`` with ``T(X_{k-1})``, formed only when another iteration follows), which
saves one triangular product a solve. The lag's error in the residual,
``(h^2/4) |T(X_k) - T(X_{k-1})|``, is comparable to the tolerance in the steady
state, so steps took more iterations: 2.88 against 2.42 a step at N = 1024 (2.01 against 1.77
s a step), 3.28 against 3.10 at N = 512 (the same time).

Measured on the idle machine, 2026-11-26 (evening), one run each: before the stage offsets
were taken from ``G(X)`` and the default degree of the start depended on the state
(``0913063``), 0.69 at N = 512 (3.38 against 4.28 iterations a step) and 0.85 at N = 1024
(3.18 against 3.32); after it, 0.65 and 0.65 (3.10 and 2.42 iterations a step; the old code
read the same energy error, 6.2e-6 and 3.1e-6, and Casimir drift, below 2e-15), and 1.61x and
1.66x on two threads. Where the time per step goes at N = 1024 (one thread, ``StepTimer``
between the run's saves, against the stage's calls timed one by one): the iteration 222 ms
(three full real products 124 ms, the lower-triangle products 80, the passes 13, ``B(X)``
5), about 56 ms a step around it (the guess, the finish with its compensation, the offset);
the half left to the target would take one iteration a step fewer again, or an iteration of
0.5 of today's. Why not a higher degree at N = 1024: the docstring of
``isoflow.methods.isomp.default_extrapolation_order``.

Measured earlier for levers 2 and 3 of issue 24 (IsoMP's quartic start on ``X - W``, on the
shared 2-core machine; ``uptime`` load in brackets):

* Part 1 (``bench_21_large_n._against_baseline(N, 50)``, load 3.0 at N = 512, 3-5 at
  N = 1024): 0.64 of the old commit's time per simulated time at N = 512 (3.38 against 4.28
  iterations per step), 0.91 at N = 1024 (3.16 against 3.32); the same energy error and
  Casimir drift (below 2e-15) in both.
* Part 2 (``bench_21_large_n._thread_scaling``): with no other process running (load 1.0-1.9,
  two runs) 1.51x and 1.48x at N = 512, 1.59x and 1.75x at N = 1024; with another process
  on a core (load 2.2-3.2) 0.08-0.15x at N = 512 and 1.07x at N = 1024 (an OpenBLAS thread
  waiting for the busy core stalls every product; hence one BLAS thread by default).
* Where one iteration goes, one thread (the stage's calls timed one by one, best of 3,
  N = 512 / 1024): the three full real products 36 / 202 ms, the lower-triangle products
  15 / 92 ms, the passes (splits, gather, combine) 4.1 / 13 ms, ``B(X)`` 2-8 / 6 ms: the
  products are 81% / 94% of it. Two BLAS threads on one full ``dgemm`` alone (idle): 1.68x
  at N = 512, 1.82x at N = 1024. With every pass on two threads the bound is about 1.6x at
  N = 512 and 1.75x at N = 1024; the passes were left serial (at most 4-6% at N = 1024, and
  a prototype of the combine pass over numba threads ran slower than the serial one as soon
  as the other core was busy). What keeps the speed-up below 1.7x is BLAS: the thin
  lower-triangle block products scale worse than a full product. Measured idle (load 2.0,
  falling, no other process busy), two BLAS threads against one on the three lower-triangle
  products with 8 / 4 / 2 equal-area row blocks: 1.40 / 1.43 / 1.55x at N = 512 (10.8 /
  11.3 / 12.0 ms with two: fewer blocks cost more flops than they gain), 1.71 / 1.78 / 1.82x
  at N = 1024; one full product 1.53x and 1.91x. At N = 512 the products alone stay below
  1.7x; at N = 1024 the serial passes (about 6%) are what remains, worth a ``prange`` only
  with a thread policy that gives a serial run's numba pool the BLAS count (today a single
  system's ``threads=2`` is 2 BLAS and 1 numba thread, the default 1 BLAS and every core for
  numba) and a guard against nesting under the ensemble driver's ``prange``.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from suite import StepTimer, benchmark, record

#: The commit before issue 24 (the planar 3M stage).
BASELINE_REV = os.environ.get("ISOFLOW_BASELINE_REV", "59b7df7")
STEPS = 50
REPEATS = 2
#: Part 2 times steps of a long run: after the first ``WARM_STEPS`` (the start's window of 16
#: offsets full), ``CHUNK_STEPS`` steps a call, as a solve's chunks take them.
WARM_STEPS = 16
CHUNK_STEPS = 8

_PROBE = """
import json, sys, time
import numpy as np
from threadpoolctl import threadpool_limits
threadpool_limits(1)
import isoflow as iso
N, steps, threads = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
prob, W0 = iso.models.euler_sphere(N=N, seed=1)
h = float(0.3 / np.linalg.norm(prob.B(W0), 2))
kw = dict(progress=False, threads=threads)
iso.solve(prob, iso.IsoMP(), W0, dt=h, n_steps=1, **kw)  # compile or load the cache
t = time.perf_counter()
sol = iso.solve(prob, iso.IsoMP(), W0, dt=h, n_steps=steps, save_every=max(1, steps // 5),
                **kw)  # diagnostics (eigenvalues) of a few states, not of every step
seconds = time.perf_counter() - t
H = np.asarray(sol.diagnostics.hamiltonian)
print(json.dumps({"seconds_per_time": seconds / (steps * h),
                  "iterations": float(sol.stats.iterations_mean),
                  "energy_error": float(np.max(np.abs(H - H[0])) / abs(H[0])),
                  "casimir_drift": float(sol.diagnostics.casimir_drift),
                  "threads": sol.stats.threads}))
"""


def _baseline_src(rev: str) -> Path | None:
    """``src`` of commit ``rev`` of this checkout's repository, extracted once per machine."""
    repo = Path(__file__).resolve().parents[1]
    dest = Path(tempfile.gettempdir()) / f"isoflow-baseline-{rev}"
    if (dest / "src" / "isoflow").is_dir():
        return dest / "src"
    try:
        dest.mkdir(parents=True, exist_ok=True)
        archive = subprocess.run(
            ["git", "-C", str(repo), "archive", rev, "src"], capture_output=True, check=True
        ).stdout
        subprocess.run(["tar", "-x", "-C", str(dest)], input=archive, check=True)
    except (OSError, subprocess.CalledProcessError):
        return None
    return dest / "src"


def _probe(src: Path | None, N: int, steps: int, threads: int = 1) -> dict[str, Any]:
    """One run with ``threads`` cores (``solve(threads=...)``) in a fresh process of the
    package in ``src`` (the baseline), else of this checkout's."""
    here = Path(__file__).resolve().parents[1] / "src"
    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    env["PYTHONPATH"] = str(src or here)
    out = subprocess.run(
        [sys.executable, "-c", _PROBE, str(N), str(steps), str(threads)],
        capture_output=True, text=True, env=env, check=True,
    )  # fmt: skip
    return json.loads(out.stdout.strip().splitlines()[-1])  # type: ignore[no-any-return]


def _against_baseline(N: int, steps: int, threads: int = 1) -> dict[str, Any]:
    src = _baseline_src(BASELINE_REV)
    name = (
        f"euler_sphere N = {N}, h ||B|| = 0.3, {steps} steps, threads={threads}: time per "
        f"simulated time / {BASELINE_REV}"
    )
    if src is None:
        why = f"the baseline commit {BASELINE_REV} is not available (git archive)"
        return record(21, name, metric="ratio", value=float("nan"), target="<= 0.5", met=None,
                      why=why)  # fmt: skip
    runs: dict[str, list[dict[str, float]]] = {"new": [], "old": []}
    for _ in range(REPEATS):
        runs["new"].append(_probe(None, N, steps, threads))
        runs["old"].append(_probe(src, N, steps, threads))
    best = {k: min(v, key=lambda r: r["seconds_per_time"]) for k, v in runs.items()}
    ratio = best["new"]["seconds_per_time"] / best["old"]["seconds_per_time"]
    ok = (
        ratio <= 0.5
        and best["new"]["casimir_drift"] < 1e-12
        and best["new"]["energy_error"] <= 1.01 * best["old"]["energy_error"]
    )
    return record(21, name, metric="ratio", value=ratio, target="<= 0.5", met=ok,
                  new=best["new"], old=best["old"])  # fmt: skip


#: The thread plans of part 2 timed alternately, group by group: the two BLAS threads last
#: and apart (an OpenBLAS thread spins on its core for a while after each call, which slowed
#: the numba threads timed next by up to 1.6x).
_GROUPS = (("1", "2"), ("2 BLAS",))


def _thread_scaling(N: int) -> dict[str, Any]:
    import isoflow as iso
    from isoflow.threads import available_cores, thread_limits

    prob, W0 = iso.models.euler_sphere(N=N, seed=1)
    h = float(0.3 / np.linalg.norm(prob.B(W0), 2))
    name = f"euler_sphere N = {N}: one iteration, 2 threads against 1"
    if available_cores() < 2:
        return record(21, name, metric="speed-up", value=float("nan"), target=">= 1.7",
                      met=None, why="one core")  # fmt: skip
    # what threads=1, threads=2 run (the pieces on numba threads, one BLAS thread each), and
    # two BLAS threads (threads=2 before the pieces ran on numba threads)
    plans = {"1": {"blas": 1, "numba": 1}, "2": {"blas": 1, "numba": 2},
             "2 BLAS": {"blas": 2, "numba": 1}}  # fmt: skip
    timers = {k: StepTimer(prob, iso.IsoMP(), W0, h) for k in plans}
    best = dict.fromkeys(plans, np.inf)
    for group in _GROUPS:  # two BLAS threads apart: OpenBLAS's threads spin after a call
        for k in group:  # the first steps, to the full window of offsets (not timed)
            with thread_limits(**plans[k]):
                timers[k].advance(WARM_STEPS)
        for rep in range(4):
            for k in group:
                with thread_limits(**plans[k]):
                    t = time.perf_counter()
                    its = timers[k].advance(CHUNK_STEPS)
                    if rep:  # the first round is the warm-up
                        best[k] = min(best[k], (time.perf_counter() - t) / its)
    speedup = best["1"] / best["2"]
    ms = {k: v * 1e3 for k, v in best.items()}
    alone = _iteration_alone(prob, W0, h, plans)
    return record(21, name, metric="speed-up", value=speedup, target=">= 1.7",
                  met=speedup >= 1.7, ms_per_iteration=ms,
                  iteration_alone=alone)  # fmt: skip


def _iteration_alone(
    prob: Any, W0: Any, h: float, plans: dict[str, dict[str, int]]
) -> dict[str, float]:
    """The stage's ``iterate`` (``B(X)``, the products and the passes after them) called by
    itself, without the step around it (the start, the finish, the offsets: serial memory
    passes): milliseconds under each of ``plans``, best of five, alternately."""
    import isoflow as iso
    from isoflow._compiled import compiled_runner
    from isoflow.threads import thread_limits

    r = compiled_runner(prob, iso.IsoMP(), W0, h)
    W = np.ascontiguousarray(np.asarray(W0, dtype=r.W.dtype).reshape(-1))
    X, G, aux = W.copy(), np.zeros_like(W), np.zeros_like(W)  # not garbage: no subnormals
    work = np.zeros((r.impl.nwork, W.size), dtype=W.dtype)
    sd, rr = np.zeros((1, 0)), np.zeros(1)
    lay = r.layout.record

    def once() -> None:
        r.impl.iterate(r.f, r.fargs, lay, r.mp, sd, W, X, G, aux, work, h, rr)

    best = dict.fromkeys(plans, np.inf)
    for group in _GROUPS:
        for rep in range(6):
            for k in group:
                with thread_limits(**plans[k]):
                    t = time.perf_counter()
                    once()
                    if rep:
                        best[k] = min(best[k], time.perf_counter() - t)
    out = {f"ms_{k}": v * 1e3 for k, v in best.items()}
    return out | {"speed_up": best["1"] / best["2"]}


@benchmark(21, "Euler on the sphere, N = 512, 1024: time per simulated time against the commit "
               "before issue 24, and two BLAS threads against one")  # fmt: skip
def run(quick: bool) -> list[dict[str, Any]]:
    sizes = (256,) if quick else (512, 1024)
    steps = 10 if quick else STEPS
    out = [_against_baseline(N, steps, threads) for N in sizes for threads in (1, 2)]
    out += [_thread_scaling(N) for N in sizes]
    return out


if __name__ == "__main__":
    for row in run("--quick" in sys.argv):
        print(json.dumps(row, default=float))
