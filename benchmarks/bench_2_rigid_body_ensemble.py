"""Benchmark 2 of the suite (see :mod:`isoflow.benchmarking`): rigid body ensemble.

Usage: ``python benchmarks/bench_2_rigid_body_ensemble.py [--quick] [--out DIR]``.
"""

from __future__ import annotations

import sys

from isoflow.benchmarking import main

if __name__ == "__main__":
    sys.exit(main(["--only", "2", *sys.argv[1:]]))
