"""Benchmark 1 of the suite (see :mod:`isoflow.benchmarking`): rigid body single.

Usage: ``python benchmarks/bench_1_rigid_body_single.py [--quick] [--out DIR]``.
"""

from __future__ import annotations

import sys

from isoflow.benchmarking import main

if __name__ == "__main__":
    sys.exit(main(["--only", "1", *sys.argv[1:]]))
