"""
Your own model at compiled speed: ``CompiledB``
===============================================

Write ``B`` once as a numba function ``f(W, out, *args)`` for one state; isoflow's compiled
loops call it directly, and the NumPy path (any solver, any method) gets its Python ``B`` from
the same function. Here: a rigid body on so(12) with random inertia, against the same ``B``
written in NumPy.

The first run compiles the loop for this kernel (seconds); with ``cache=True`` numba keeps the
machine code in ``NUMBA_CACHE_DIR`` (or beside the source file), so a new process only loads it.
"""

import inspect
import os
import subprocess
import sys
import time

import numba
import numpy as np
from matplotlib.figure import Figure

import isoflow as iso

n = 12
rng = np.random.default_rng(1)
d = 1.0 / rng.uniform(1.0, 4.0, n)
C = 0.5 * (d[:, None] + d[None, :])


@numba.njit(cache=True)
def rigid_body_B(W, out, C):
    m = W.shape[0]
    for i in range(m):
        for j in range(m):
            out[i, j] = -C[i, j] * W[i, j]


alg = iso.algebras.so(n)
compiled = iso.IsospectralProblem(algebra=alg, kernel=iso.CompiledB(rigid_body_B, (C,)))
numpy_path = iso.IsospectralProblem(B=lambda W: -C * W, algebra=alg)
W0 = alg.random(0)
steps = 2000 if os.environ.get("ISOFLOW_DOCS_QUICK") == "1" else 10000


def run(problem):
    t = time.perf_counter()
    sol = iso.solve(problem, iso.IsoMP(), W0, dt=0.05, n_steps=steps, save_every=steps)
    return sol, time.perf_counter() - t


if os.environ.get("ISOFLOW_EXAMPLE_CHILD") == "1":  # the timing of a new process (below)
    sol, seconds = run(compiled)
    print(f"{sol.stats.compile_time:.3f} {seconds:.3f}")
    sys.exit(0)

first, t_first = run(compiled)
second, t_second = run(compiled)
slow, t_numpy = run(numpy_path)
print(
    f"first compiled run : {t_first:.2f} s (compile or cache load {first.stats.compile_time:.2f} s)"
)
print(f"second run         : {t_second:.3f} s, runner: {second.stats.runner}")
print(f"NumPy path         : {t_numpy:.3f} s, runner: {slow.stats.runner}")
print(f"same final state   : {np.abs(second.y_final - slow.y_final).max():.1e} apart")

# %%
# A new Python process running the same solve loads the compiled loop from numba's cache
# instead of compiling it.

env = dict(os.environ, ISOFLOW_EXAMPLE_CHILD="1")
script = inspect.getsourcefile(rigid_body_B.py_func)  # this file
out = subprocess.run(
    [sys.executable, script], env=env, capture_output=True, text=True, check=True
).stdout.split()
load, t_child = float(out[-2]), float(out[-1])
print(f"new process: loading the loop took {load:.2f} s; the solve, with the first-use")
print(f"imports of that process, {t_child:.2f} s")

fig = Figure(figsize=(7, 3.4), layout="constrained")
ax = fig.subplots()
labels = [
    f"compiled, first run\n(compile or cache load {first.stats.compile_time:.2f} s)",
    "compiled, warm",
    "NumPy path",
]
bars = ax.bar(labels, [t_first, t_second, t_numpy], color=["C1", "C0", "C7"])
ax.bar_label(bars, fmt="%.3f s", fontsize=8)
ax.set(ylabel="wall time [s]", yscale="log",
       title=f"so({n}) rigid body, IsoMP, {steps} steps of h = 0.05")  # fmt: skip
