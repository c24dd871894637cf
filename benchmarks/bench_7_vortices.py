"""Benchmark 7 of the suite (see :mod:`isoflow.benchmarking`): compiled point-vortex loops.

IsoMP time per step of the compiled loop (``PairwiseVortex`` kernel) against the NumPy path
(``kernel=None``): the paper's hyperbolic configuration 1 and 3 / 100 vortices on the sphere.

Usage: ``python benchmarks/bench_7_vortices.py [--quick] [--out DIR]``.
"""

from __future__ import annotations

import sys

from isoflow.benchmarking import main

if __name__ == "__main__":
    sys.exit(main(["--only", "7", *sys.argv[1:]]))
