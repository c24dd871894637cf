"""Spin and vortex runs timed through :func:`isoflow.solve` alone, so older commits run them too.

Each case is one run a user makes on :math:`(\\mathbb{R}^3,\\times)^N` with the method's
defaults and the default threads: one warm-up solve of two steps (compilation or numba's
cache), then ``steps`` steps timed, one saved row. Prints one JSON line: milliseconds a step,
iterations a step and the largest change of a particle's length ``|w_i|`` over the run.

Cases (``h`` in brackets):

* ``chain``: 10^5 random spins, IsoMP (0.1);
* ``lattice``: the 256 x 256 lattice of benchmark 19 without noise, IsoMP (0.05);
* ``thermal-lattice``, ``thermal-lattice-cayley``: the same at ``T = 0.5``, damping 0.1,
  :class:`isoflow.StochasticIsoMP` with either update (0.05);
* ``noisy-chain``: the chain with site noise 0.1, the stochastic midpoint (0.1);
* ``thermal-chain``: 10^5 spins at ``T = 0.5``, damping 0.1, the stochastic midpoint (0.05);
* ``vortices``: 100 vortices on the sphere of benchmark 7, IsoMP (0.01).

Side by side with an older commit (a ``git worktree`` at ``OLD`` with a numba cache of its
own), alternating processes::

    for i in 1 2; do for case in chain lattice thermal-lattice; do
      PYTHONPATH=OLD/src NUMBA_CACHE_DIR=/tmp/nc python benchmarks/side_by_side_spins.py $case 40
      python benchmarks/side_by_side_spins.py $case 40
    done; done

(``OPENBLAS_NUM_THREADS=1`` as the test suite; the runs use numba's threads as users get
them). ``docs/user_guide/solvers.rst`` quotes such a run.
"""

from __future__ import annotations

import dataclasses
import json
import sys
import time
from typing import Any

import numpy as np


def _random_chain(N: int) -> tuple[Any, np.ndarray]:
    import isoflow as iso

    rng = np.random.default_rng(0)
    w = rng.standard_normal((N, 3))
    prob, _ = iso.models.heisenberg_chain(N)
    return prob, w / np.linalg.norm(w, axis=1)[:, None]


def _lattice(**thermal: Any) -> tuple[Any, np.ndarray]:
    import isoflow as iso

    common = {"J": -1.0, "field": (0.0, 0.0, 0.2), "initial": "random", "seed": 0}
    return iso.models.spin_lattice((256, 256), **common, **thermal)  # type: ignore[no-any-return]


def _vortices(N: int) -> tuple[Any, np.ndarray]:
    import isoflow as iso

    rng = np.random.default_rng(0)
    k = np.arange(N) + 0.5
    z = 1.0 - 2.0 * k / N
    phi = np.pi * (1.0 + np.sqrt(5.0)) * k
    r = np.sqrt(1.0 - z * z)
    x = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)
    return iso.models.sphere_vortices(positions=x, circulations=rng.uniform(0.5, 1.5, N))  # type: ignore[no-any-return]


def case(name: str) -> tuple[Any, np.ndarray, Any, float]:
    """``(problem, y0, method, h)`` of a case (the module docstring)."""
    import isoflow as iso
    from isoflow.noise import TransportNoise

    thermal = {"temperature": 0.5, "damping": 0.1, "noise_seed": 1}
    if name == "chain":
        return (*_random_chain(100_000), iso.IsoMP(), 0.1)
    if name == "lattice":
        return (*_lattice(), iso.IsoMP(), 0.05)
    if name in ("thermal-lattice", "thermal-lattice-cayley"):
        update = "cayley" if name.endswith("cayley") else "midpoint"
        return (*_lattice(**thermal), iso.StochasticIsoMP(update=update), 0.05)
    if name == "noisy-chain":
        prob, w = _random_chain(100_000)
        prob = dataclasses.replace(prob, noise=TransportNoise(site=0.1, seed=1))
        return prob, w, iso.StochasticIsoMP(), 0.1
    if name == "thermal-chain":
        prob, w = iso.models.heisenberg_chain(
            100_000, initial="random", seed=2, temperature=0.5, damping=0.1, noise_seed=3
        )
        return prob, w, iso.StochasticIsoMP(), 0.05
    if name == "vortices":
        return (*_vortices(100), iso.IsoMP(), 0.01)
    raise SystemExit(f"unknown case {name!r}")


def main(name: str, steps: int) -> dict[str, float]:
    import isoflow as iso

    prob, y0, method, h = case(name)
    iso.solve(prob, method, y0, dt=h, n_steps=2, progress=False, diagnostics=False)
    t = time.perf_counter()
    sol = iso.solve(prob, method, y0, dt=h, n_steps=steps, save_every=steps, progress=False,
                    diagnostics=False)  # fmt: skip
    seconds = time.perf_counter() - t
    lengths = np.linalg.norm(np.asarray(sol.y_final), axis=-1)
    drift = np.abs(lengths - np.linalg.norm(np.asarray(y0), axis=-1)).max()
    return {"ms_per_step": seconds / steps * 1e3,
            "iterations_per_step": float(sol.stats.iterations_mean),
            "length_drift": float(drift)}  # fmt: skip


if __name__ == "__main__":
    print(json.dumps(main(sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 40)))
