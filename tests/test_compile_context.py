"""A compiled loop gives the same states whether it was compiled in the run's process or loaded
from numba's on-disk cache.

A run's first process usually compiles its loop and a resume (or any later run) loads it from
the cache, so resuming bit for bit needs the two to agree to the last bit. They did not on the
dense BLAS layout while its tile pass let LLVM reassociate (states 1e-16 apart from the first
saved row: the reassociation depended on what else the compiler saw). Two fresh processes on
one new cache directory: the first compiles, the second loads. The cases cover every compiled
function that moves a state and once was compiled with ``reassoc``: the BLAS tiles and real
planes, the spin chain's fused sweeps (serial and threaded, IsoMP, the spherical and the
stochastic midpoint, compensated and plain), Anderson mixing's inner products, and the sphere's
dissipative flow.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np

#: su(64) runs on the complex BLAS tiles, su(128) on the real planes with 3M products.
_SCRIPT = """
import dataclasses
import sys
import numpy as np
import isoflow as iso
from isoflow.noise import TransportNoise

out = {}

def run(name, problem, method, y0, runner, dt=0.01, n=60, **kw):
    sol = iso.solve(problem, method, y0, dt=dt, n_steps=n, save_every=n // 3, progress=False,
                    **kw)
    assert sol.stats.runner.startswith(runner), (name, sol.stats.runner)
    out[name] = sol.ys

for N in (64, 128):
    problem, y0 = iso.models.euler_sphere(N)
    run(f"su({N})", problem, iso.IsoMP(), y0, "compiled, dense su")
chain, s0 = iso.models.heisenberg_chain(3000, initial="random", seed=2)
run("chain", chain, iso.IsoMP(), s0, "compiled, spin chain", dt=0.05, n=30)
run("chain plain", chain, iso.IsoMP(compensated=False), s0, "compiled, spin chain", dt=0.05, n=30)
run("chain smm", chain, iso.SphericalMidpoint(), s0, "compiled, spin chain", dt=0.05, n=30)
noisy = dataclasses.replace(chain, noise=TransportNoise(site=0.1, seed=1))
run("chain noise", noisy, iso.StochasticIsoMP(), s0, "compiled, spin chain", dt=0.05, n=30)
long_chain, s1 = iso.models.heisenberg_chain(200_000, initial="random", seed=3)
threaded = iso.threads.available_cores() >= 2
run("chain threads", long_chain, iso.IsoMP(), s1,
    "compiled, spin chain ((3, N) layout, threaded" if threaded else "compiled, spin chain",
    dt=0.05, n=6, threads=2)
body, w0 = iso.models.rigid_body(6)
run("anderson", body, iso.IsoMP(solver=iso.FixedPoint(anderson=3)), w0, "compiled, dense so",
    dt=0.1, n=30)
viscous, v0 = iso.models.euler_sphere(24, viscosity=1e-2)
run("viscous", viscous, iso.Strang(iso.IsoMP()), v0, "compiled, dense su", dt=0.05, n=30)
np.savez(sys.argv[1], **out)
"""


def _run(cache: Path, out: Path) -> dict[str, np.ndarray]:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    done = subprocess.run([sys.executable, "-c", _SCRIPT, str(out)], env=env,
                          capture_output=True, text=True, timeout=900)  # fmt: skip
    assert done.returncode == 0, done.stderr
    with np.load(out) as data:
        return {k: data[k] for k in data.files}


def test_compiled_in_the_process_and_loaded_from_the_cache_agree_bit_for_bit(
    tmp_path: Path,
) -> None:
    cache = tmp_path / "cache"
    compiled = _run(cache, tmp_path / "compiled.npz")
    assert any(cache.rglob("*.nbi")), "the first process wrote nothing to the cache"
    loaded = _run(cache, tmp_path / "loaded.npz")
    for name, ys in compiled.items():
        assert ys.tobytes() == loaded[name].tobytes(), (
            f"{name}: largest difference {np.abs(ys - loaded[name]).max():.1e}"
        )
