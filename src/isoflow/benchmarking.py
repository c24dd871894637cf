r"""Benchmark suite of the fast paths: ratios against baselines timed in the same run.

Each benchmark implements and times its own baseline in the same process and reports a ratio,
so the numbers transfer between machines:

1. ``so(10)`` rigid body, one system: time per step of :class:`~isoflow.IsoMP` against a
   straightforward NumPy implementation of the paper's iteration (allocating, Python loops,
   ``X_0 = W_k``). Target: speed-up >= 6.
2. Ensemble of ``10^4`` ``so(10)`` rigid bodies: time per system-step against the same
   iteration on the stacked ensemble with batched ``numpy.matmul``. Target: speed-up >= 2.
3. Dense ``so(n)``, ``u(n)``, ``n = 256, 512, 1024``: time per fixed-point iteration against
   the bare time of two ``n x n`` matrix products (``numpy.matmul`` into preallocated
   outputs). Target: ratio <= 1.15.
4. Heisenberg spin chain, ``N = 100 .. 10^7``: time per iteration against the memory-traffic
   bound, ``72 N`` bytes (read ``x`` and ``w``, write ``G``) over the triad bandwidth
   ``a = b + s c`` measured in the same run. Target: ratio <= 2 for ``N >= 10^6``.
5. IsoMP against the spherical midpoint, time per step on the spin chain,
   ``N = 10 .. 10^6``. Target: ratio <= 1.
6. Mean fixed-point iterations per step on the paper's rigid body and spin chain (``h = 0.1``)
   at the default (``rtol = 1e-14``) and the tightest (``1e-16``) tolerance, paper's
   ``X_0 = W_k`` against the default extrapolation.
7. Point vortices (paper's hyperbolic configuration 1, ``h = 0.01``; ``N = 3`` and
   ``N = 100`` vortices on the sphere, ``h = 0.01``), one system: IsoMP time per step of the
   compiled loop (``PairwiseVortex`` kernel) against the NumPy path (``kernel=None``). No
   target; the speed-up is reported.

Run ``isoflow bench`` or ``python -m isoflow.benchmarking`` (``--quick`` for a short run,
``--only 1,4``); results go to ``<out>/benchmarks.json`` and ``<out>/benchmarks.md``.
Timings are the best of several repeats with :func:`time.perf_counter`; numba compilation is
excluded (every path is warmed up first). Threads follow :mod:`isoflow.threads`.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import platform
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numba
import numpy as np

__all__ = ["main", "run", "spin_chain_cost", "to_markdown"]


# ---- helpers ------------------------------------------------------------------------------------
def _median_time(fn: Callable[[], Any], repeats: int = 5, min_time: float = 0.0) -> float:
    """Best wall time of ``fn()`` over ``repeats`` runs (after one warm-up run).

    The minimum, not the median: on a shared machine other load only ever adds time, and
    the baseline and the fast path are timed the same way, so their ratio stays fair.
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


def _paired_time(
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


def machine() -> dict[str, Any]:
    """Description of the machine and the thread pools."""
    import numba

    from .threads import current_threads

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


def _paper_iteration_numpy(W: np.ndarray, c: np.ndarray, h: float, rtol: float) -> tuple:
    """Baseline: the paper's IsoMP step written plainly (allocating; ``X_0 = W``)."""
    X = W
    tol = rtol * np.sqrt(np.sum(W * W, axis=(-2, -1)))
    it = 0
    for it in range(1, 201):  # noqa: B007
        B = -c * X
        BX = B @ X
        G = W + 0.5 * h * (BX - X @ B) + 0.25 * h * h * (BX @ B)
        G = 0.5 * (G - np.swapaxes(G, -1, -2))
        r = np.sqrt(np.sum((G - X) ** 2, axis=(-2, -1)))
        if np.all(r <= tol):
            break
        X = G
    B = -c * X
    Wn = W + h * (B @ X - X @ B)
    return 0.5 * (Wn - np.swapaxes(Wn, -1, -2)), it


# ---- 1, 2: small dense ------------------------------------------------------------------------
def bench_rigid_single(quick: bool) -> dict[str, Any]:
    import isoflow as iso

    prob, W0 = iso.models.rigid_body(10)
    c = prob.parameters["inverse_inertia"]
    h = 0.1
    n_fast = 2000 if not quick else 500
    n_base = 200 if not quick else 50
    m = iso.IsoMP()

    def fast() -> Any:
        return m.advance(prob, W0, h, n_fast)

    def base() -> int:
        W, tot = W0, 0
        for _ in range(n_base):
            W, it = _paper_iteration_numpy(W, c, h, 1e-14)
            tot += it
        return tot

    t_fast, t_base = _paired_time(fast, base)
    t_fast /= n_fast
    t_base /= n_base
    it_fast = fast().iterations_total / n_fast
    it_base = base() / n_base
    return {
        "id": 1,
        "name": "so(10) rigid body, one system: time per step",
        "fast_us_per_step": t_fast * 1e6,
        "baseline_us_per_step": t_base * 1e6,
        "fast_us_per_iteration": t_fast / it_fast * 1e6,
        "baseline_us_per_iteration": t_base / it_base * 1e6,
        "iterations_per_step": {"fast": it_fast, "baseline": it_base},
        "metric": "speed-up (baseline / fast)",
        "value": t_base / t_fast,
        "target": ">= 6",
        "met": t_base / t_fast >= 6.0,
    }


def bench_rigid_ensemble(quick: bool) -> dict[str, Any]:
    import isoflow as iso

    from .threads import available_cores, thread_limits

    M = 10_000 if not quick else 2_000
    prob, _ = iso.models.rigid_body(10)
    c = prob.parameters["inverse_inertia"]
    W = iso.algebras.so(10).random(seed=0, batch=(M,), scale=0.1)
    h = 0.1
    n_fast, n_base = (20, 4) if not quick else (5, 2)
    m = iso.IsoMP()
    cores = available_cores()
    with thread_limits(blas=1, numba=cores):
        it_fast = m.advance(prob, W, h, n_fast).iterations_total / (n_fast * M)

        def base() -> None:
            Y = W
            for _ in range(n_base):
                Y, _ = _paper_iteration_numpy(Y, c, h, 1e-14)

        t_fast, t_base = _paired_time(lambda: m.advance(prob, W, h, n_fast), base, repeats=3)
        t_fast /= n_fast * M
        t_base /= n_base * M
    return {
        "id": 2,
        "name": f"ensemble of {M} so(10) rigid bodies: time per system-step",
        "fast_us_per_system_step": t_fast * 1e6,
        "baseline_us_per_system_step": t_base * 1e6,
        "fast_us_per_system_iteration": t_fast / it_fast * 1e6,
        "threads": {"numba": cores, "blas": 1},
        "metric": "speed-up (stacked numpy / fast)",
        "value": t_base / t_fast,
        "target": ">= 2",
        "met": t_base / t_fast >= 2.0,
    }


# ---- 3: large dense ---------------------------------------------------------------------------
def bench_large_dense(quick: bool) -> list[dict[str, Any]]:
    import isoflow as iso

    from ._fast.blas import lower_blocks, lower_product
    from ._fast.kernels import ElementwiseLinear
    from .threads import available_cores, thread_limits

    sizes = (256, 512, 1024) if not quick else (256,)
    out = []
    cores = available_cores()
    with thread_limits(blas=cores, numba=1):
        for space in ("so", "u"):
            for n in sizes:
                alg = getattr(iso.algebras, space)(n)
                d = np.linspace(0.5, 1.5, n)
                C = -(d[:, None] + d[None, :]) / 2
                prob = iso.IsospectralProblem(
                    B=ElementwiseLinear(C).evaluate, algebra=alg, kernel=ElementwiseLinear(C)
                )
                W0 = alg.random(seed=1, scale=1.0 / n)
                m = iso.IsoMP()
                steps = {256: 8, 512: 4}.get(n, 2)  # one advance call, amortized
                res: dict[str, Any] = {}

                def fast(m=m, prob=prob, W0=W0, steps=steps, res=res) -> None:
                    res["adv"] = m.advance(prob, W0, 0.1, steps)

                A = np.ascontiguousarray(alg.random(seed=2))
                Bm = np.ascontiguousarray(alg.random(seed=3))
                P = np.empty_like(A)
                T = np.empty_like(A)

                def two(A=A, Bm=Bm, P=P, T=T) -> None:
                    np.matmul(Bm, A, out=P)
                    np.matmul(P, Bm, out=T)

                blocks = lower_blocks(n)

                def half(A=A, Bm=Bm, T=T, blocks=blocks) -> None:
                    lower_product(A, Bm, T, blocks)

                def full(A=A, Bm=Bm, T=T) -> None:
                    np.matmul(A, Bm, out=T)

                t_fast, t_two = _paired_time(fast, two, repeats=3)
                t_half, t_full = _paired_time(half, full, repeats=3)
                iters = res["adv"].iterations_total
                ratio = t_fast / iters / t_two
                out.append(
                    {
                        "id": 3,
                        "name": f"dense {space}({n}): time per iteration / two products",
                        "ms_per_iteration": t_fast / iters * 1e3,
                        "ms_two_products": t_two * 1e3,
                        "half_product_fraction": t_half / t_full,
                        "iterations": iters,
                        "threads": {"blas": cores, "numba": 1},
                        "metric": "ratio (iteration / two products)",
                        "value": ratio,
                        "target": "<= 1.15",
                        "met": ratio <= 1.15,
                    }
                )
    return out


# ---- 4, 5: spin chains ------------------------------------------------------------------------
def triad_bandwidth(n: int = 20_000_000, parallel: bool = False) -> float:
    """Bytes per second of ``a = b + s c`` (numba, ``n`` doubles, 24 bytes per element)."""
    a = np.zeros(n)
    b = np.random.default_rng(0).random(n)
    c = np.random.default_rng(1).random(n)
    f = _triad_par if parallel else _triad_ser
    t = _median_time(lambda: f(a, b, c, 3.0), repeats=7)
    return 24.0 * n / t


def _triad_impl(a, b, c, s):  # type: ignore[no-untyped-def]
    for i in range(a.size):
        a[i] = b[i] + s * c[i]


def _triad_par_impl(a, b, c, s):  # type: ignore[no-untyped-def]
    for i in numba.prange(a.size):
        a[i] = b[i] + s * c[i]


def _lazy_triads() -> None:
    global _triad_ser, _triad_par
    _triad_ser = numba.njit(cache=False)(_triad_impl)
    _triad_par = numba.njit(cache=False, parallel=True)(_triad_par_impl)


_triad_ser: Any = None
_triad_par: Any = None


def _chain(N: int, seed: int = 0) -> tuple[Any, np.ndarray]:
    import isoflow as iso

    from ._fast.kernels import SpinNeighbourSum

    prob, w0 = iso.models.heisenberg_chain(N, initial="random", seed=seed)
    if prob.kernel is None:
        prob = dataclasses.replace(prob, kernel=SpinNeighbourSum(-1.0))
    return prob, w0


def _smm_advance(prob: Any, w: np.ndarray, h: float, n: int, state: Any) -> Any:
    import isoflow as iso

    from ._fast import dispatch

    s = iso.SphericalMidpoint()
    res = dispatch.smm_advance(s, prob, w, h, n, state)
    return res if res is not None else s.advance(prob, w, h, n, state)


def bench_spin_bandwidth(quick: bool) -> list[dict[str, Any]]:
    import isoflow as iso

    from .threads import available_cores, thread_limits

    _lazy_triads()
    Ns = (100, 10_000, 1_000_000, 10_000_000) if not quick else (100, 10_000, 1_000_000)
    out = []
    cores = available_cores()
    bw = {1: triad_bandwidth(parallel=False)}
    if cores > 1:
        with thread_limits(blas=1, numba=cores):
            bw[cores] = triad_bandwidth(parallel=True)
    for N in Ns:
        prob, w0 = _chain(N)
        m = iso.IsoMP()
        warm = m.advance(prob, w0, 0.1, 3)
        steps = max(20, min(200, int(3e8 // (N * 15))))
        best: dict[str, Any] | None = None
        for threads in sorted(bw):
            with thread_limits(blas=1, numba=threads):
                res: dict[str, Any] = {}

                def run_(res=res, prob=prob, warm=warm, steps=steps, m=m) -> None:
                    res["adv"] = m.advance(prob, warm.y, 0.1, steps, warm.state)

                t = _median_time(run_, repeats=3 if N < 10**7 else 1)
            per_it = t / res["adv"].iterations_total
            bound = 72.0 * N / max(bw.values())  # the strictest: the best bandwidth measured
            cand = {
                "threads": threads,
                "ns_per_spin_iteration": per_it / N * 1e9,
                "bound_ns_per_spin": bound / N * 1e9,
                "triad_GBps": max(bw.values()) / 1e9,
                "triad_GBps_per_threads": {str(k): v / 1e9 for k, v in bw.items()},
                "ratio": per_it / bound,
            }
            if best is None or cand["ns_per_spin_iteration"] < best["ns_per_spin_iteration"]:
                best = cand
        assert best is not None
        out.append(
            {
                "id": 4,
                "name": f"spin chain N = {N:.0e}: time per iteration / memory bound",
                **best,
                "metric": "ratio (iteration / (72 N bytes / triad bandwidth))",
                "value": best["ratio"],
                "target": "<= 2 for N >= 1e6" if N >= 10**6 else "(no target, N < 1e6)",
                "met": best["ratio"] <= 2.0 if N >= 10**6 else None,
            }
        )
    return out


def spin_chain_cost(
    Ns: Sequence[int] = (10, 100, 1_000, 10_000, 100_000, 1_000_000),
    h: float = 0.1,
    seed: int = 0,
    min_time: float = 0.3,
) -> list[dict[str, Any]]:
    """IsoMP and spherical midpoint time per step on the Heisenberg chain (random spins).

    Both methods use their compiled fast paths and the default fixed-point solver; each is
    warmed up (5 steps) and then timed over enough steps to last about ``min_time`` seconds.
    Returns one record per ``N``: seconds per step and mean iterations per step of each
    method, and the ratio IsoMP / SMM. Reusable by the ``spin-chain-cost`` experiment.
    """
    import isoflow as iso

    rows = []
    for N in Ns:
        prob, w0 = _chain(int(N), seed)
        m = iso.IsoMP()
        wi = m.advance(prob, w0, h, 5)
        ws = _smm_advance(prob, w0, h, 5, None)
        steps = max(3, int(min_time / max(N * 15 * 4e-9, 2e-6)))
        ri: dict[str, Any] = {}
        rs: dict[str, Any] = {}

        def iso_run(ri=ri, prob=prob, wi=wi, steps=steps, m=m) -> None:
            ri["a"] = m.advance(prob, wi.y, h, steps, wi.state)

        def smm_run(rs=rs, prob=prob, ws=ws, steps=steps) -> None:
            rs["a"] = _smm_advance(prob, ws.y, h, steps, ws.state)

        ti, ts = _paired_time(iso_run, smm_run, repeats=5)
        ti /= steps
        ts /= steps
        rows.append(
            {
                "N": int(N),
                "isomp_s_per_step": ti,
                "smm_s_per_step": ts,
                "isomp_iterations_per_step": ri["a"].iterations_total / steps,
                "smm_iterations_per_step": rs["a"].iterations_total / steps,
                "ratio": ti / ts,
            }
        )
    return rows


def plot_spin_chain_cost(rows: list[dict[str, Any]], path: str | Path) -> Path:
    """Log-log figure of :func:`spin_chain_cost` (time per step against ``N``) as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    N = [r["N"] for r in rows]
    fig, ax = plt.subplots(figsize=(5.0, 3.6), dpi=120)
    ax.loglog(N, [r["isomp_s_per_step"] for r in rows], "o-", label="IsoMP")
    ax.loglog(N, [r["smm_s_per_step"] for r in rows], "s--", label="spherical midpoint")
    ax.set_xlabel("number of spins N")
    ax.set_ylabel("time per step [s]")
    ax.set_title("Heisenberg chain, h = 0.1, rtol = 1e-14")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(p)
    plt.close(fig)
    return p


def bench_isomp_vs_smm(quick: bool, figure: str | Path | None = None) -> list[dict[str, Any]]:
    from .threads import thread_limits

    Ns = (10, 100, 1_000, 10_000, 100_000, 1_000_000) if not quick else (10, 1_000, 100_000)
    with thread_limits(blas=1):
        rows = spin_chain_cost(Ns, min_time=0.3 if not quick else 0.1)
    if figure is not None:
        plot_spin_chain_cost(rows, figure)
    return [
        {
            "id": 5,
            "name": f"spin chain N = {r['N']:.0e}: IsoMP / spherical midpoint per step",
            **r,
            "metric": "ratio (IsoMP / SMM time per step)",
            "value": r["ratio"],
            "target": "<= 1.0",
            "met": r["ratio"] <= 1.0,
        }
        for r in rows
    ]


# ---- 6: iterations ------------------------------------------------------------------------------
def bench_iterations(quick: bool) -> list[dict[str, Any]]:
    import isoflow as iso

    from .methods._base import Method

    out = []
    n_steps = 1000 if not quick else 200
    rb, W0 = iso.models.rigid_body(10)
    sc, w0 = iso.models.heisenberg_chain(100)
    for label, prob, y0 in (("rigid body so(10)", rb, W0), ("spin chain N = 100", sc, w0)):
        plain = dataclasses.replace(prob, kernel=None)
        for rtol in (1e-14, 1e-16):
            fp = iso.FixedPoint(rtol=rtol)
            rec: dict[str, Any] = {}
            for guess in ("state", "extrapolate"):
                a = Method.advance(iso.IsoMP(solver=fp, initial_guess=guess), plain, y0, 0.1,
                                   n_steps)  # fmt: skip
                rec[guess] = a.iterations_total / n_steps
                rec[f"y_{guess}"] = a.y
            if "spin" in label:
                s = Method.advance(iso.SphericalMidpoint(solver=fp), plain, y0, 0.1, n_steps)
                rec["smm"] = s.iterations_total / n_steps
            diff = float(np.max(np.abs(rec.pop("y_state") - rec.pop("y_extrapolate"))))
            saving = 1.0 - rec["extrapolate"] / rec["state"]
            out.append(
                {
                    "id": 6,
                    "name": f"{label}, rtol = {rtol:.0e}: mean iterations per step",
                    "iterations_paper_X0_eq_W": rec["state"],
                    "iterations_default": rec["extrapolate"],
                    **({"iterations_smm": rec["smm"]} if "smm" in rec else {}),
                    "max_difference_of_answers": diff,
                    "metric": "iterations saved (1 - default / paper)",
                    "value": saving,
                    "target": ">= 0.25 (rigid body)" if "rigid" in label else "(none)",
                    "met": (saving >= 0.25 and diff <= 1e-13) if "rigid" in label else None,
                }
            )
    return out


# ---- 7: point vortices -------------------------------------------------------------------------
def _vortex_cases() -> list[tuple[str, Any, np.ndarray]]:
    """The paper's hyperbolic configuration 1, and 3 and 100 vortices on the sphere.

    The sphere positions are Fibonacci points (well separated, so ``h = 0.01`` is a moderate
    step), the circulations random in ``[0.5, 1.5]`` (seeded; one sign, so that no dipole
    pairs form and run off).
    """
    import isoflow as iso

    cases: list[tuple[str, Any, np.ndarray]] = []
    prob, w0 = iso.models.hyperbolic_vortices(config=1)
    cases.append(("hyperbolic vortices, paper config 1 (N = 3)", prob, w0))
    rng = np.random.default_rng(0)
    for N in (3, 100):
        k = np.arange(N) + 0.5
        z = 1.0 - 2.0 * k / N
        phi = np.pi * (1.0 + np.sqrt(5.0)) * k
        r = np.sqrt(1.0 - z * z)
        x = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)
        circ = rng.uniform(0.5, 1.5, N)
        prob, x0 = iso.models.sphere_vortices(positions=x, circulations=circ)
        cases.append((f"sphere vortices, N = {N}", prob, x0))
    return cases


def bench_vortices(quick: bool) -> list[dict[str, Any]]:
    import isoflow as iso

    from .threads import thread_limits

    h = 0.01
    m = iso.IsoMP()
    out = []
    with thread_limits(blas=1, numba=1):  # one system: the compiled loop is serial
        for label, prob, y0 in _vortex_cases():
            plain = dataclasses.replace(prob, kernel=None)
            N = y0.shape[-2]
            warm = m.advance(prob, y0, h, 5)  # a running warm start for both
            n = 2000 if N <= 10 else 100  # the same steps for both paths
            if quick:
                n //= 4
            res: dict[str, Any] = {}

            def fast(res=res, prob=prob, warm=warm, n=n) -> None:
                res["fast"] = m.advance(prob, warm.y, h, n, warm.state)

            def base(res=res, plain=plain, warm=warm, n=n) -> None:
                res["base"] = m.advance(plain, warm.y, h, n, warm.state)

            t_fast, t_base = _paired_time(fast, base, repeats=5 if not quick else 3)
            its = {k: res[k].iterations_total / n for k in ("fast", "base")}
            if res["fast"].n_done != n or res["base"].n_done != n:  # pragma: no cover
                raise RuntimeError(f"benchmark 7: {label} failed before {n} steps")
            t_fast /= n
            t_base /= n
            out.append(
                {
                    "id": 7,
                    "name": f"{label}: IsoMP time per step, compiled / NumPy path",
                    "N": N,
                    "h": h,
                    "steps": n,
                    "fast_us_per_step": t_fast * 1e6,
                    "numpy_us_per_step": t_base * 1e6,
                    "fast_us_per_iteration": t_fast / its["fast"] * 1e6,
                    "numpy_us_per_iteration": t_base / its["base"] * 1e6,
                    "iterations_per_step": {"fast": its["fast"], "numpy": its["base"]},
                    "threads": {"blas": 1, "numba": 1},
                    "metric": "speed-up (NumPy path / compiled)",
                    "value": t_base / t_fast,
                    "target": "(none)",
                    "met": None,
                }
            )
    return out


# ---- driver -------------------------------------------------------------------------------------
def run(only: Sequence[int] | None = None, quick: bool = False,
        figure: str | Path | None = None) -> dict[str, Any]:  # fmt: skip
    """Run the selected benchmarks; returns ``{"machine", "results", "wall_time"}``."""
    sel = set(only) if only else {1, 2, 3, 4, 5, 6, 7}
    start = time.perf_counter()
    results: list[dict[str, Any]] = []
    steps: list[tuple[int, Callable[[], Any]]] = [
        (6, lambda: bench_iterations(quick)),
        (1, lambda: [bench_rigid_single(quick)]),
        (2, lambda: [bench_rigid_ensemble(quick)]),
        (5, lambda: bench_isomp_vs_smm(quick, figure)),
        (4, lambda: bench_spin_bandwidth(quick)),
        (3, lambda: bench_large_dense(quick)),
        (7, lambda: bench_vortices(quick)),
    ]
    for k, fn in steps:
        if k in sel:
            t = time.perf_counter()
            res = fn()
            print(f"benchmark {k}: {time.perf_counter() - t:.1f} s", flush=True)
            results.extend(res)
    results.sort(key=lambda r: r["id"])
    return {"machine": machine(), "results": results, "wall_time": time.perf_counter() - start}


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


def _jsonable(x: Any) -> Any:
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return str(x)
    return x


def main(argv: list[str] | None = None) -> int:
    """Command line: ``isoflow bench [--out DIR] [--quick] [--only 1,2,...] [--figure PNG]``."""
    ap = argparse.ArgumentParser(prog="isoflow bench", description=__doc__.split("\n")[0])
    ap.add_argument("--out", default="benchmark-results", help="output directory")
    ap.add_argument("--quick", action="store_true", help="smaller sizes (about a minute)")
    ap.add_argument("--only", default="", help="comma-separated benchmark numbers (1-7)")
    ap.add_argument("--figure", default=None, help="write the spin-chain-cost PNG here")
    args = ap.parse_args(argv)
    only = [int(k) for k in args.only.split(",") if k.strip()] if args.only else None
    report = run(only, args.quick, args.figure)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "benchmarks.json").write_text(json.dumps(_jsonable(report), indent=2))
    table = to_markdown(report)
    (out / "benchmarks.md").write_text(table)
    print(table)
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
