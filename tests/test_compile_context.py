"""A compiled loop gives the same states whether it was compiled in the run's process or loaded
from numba's on-disk cache.

A run's first process usually compiles its loop and a resume (or any later run) loads it from
the cache, so resuming bit for bit needs the two to agree to the last bit. They did not on the
dense BLAS layout while its tile pass let LLVM reassociate (states 1e-16 apart from the first
saved row: the reassociation depended on what else the compiler saw). Two fresh processes on
one new cache directory: the first compiles, the second loads.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np

#: su(64) runs on the complex BLAS tiles, su(128) on the real planes with 3M products.
_SCRIPT = """
import sys
import numpy as np
import isoflow as iso

out = {}
for N in (64, 128):
    problem, y0 = iso.models.euler_sphere(N)
    sol = iso.solve(problem, iso.IsoMP(), y0, dt=0.01, n_steps=60, save_every=20, progress=False)
    assert sol.stats.runner.startswith("compiled, dense su"), sol.stats.runner
    out[f"N{N}"] = sol.ys
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
