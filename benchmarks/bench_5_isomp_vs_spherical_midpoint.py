"""Benchmark 5 of the suite (see :mod:`isoflow.benchmarking`): isomp vs spherical midpoint.

Usage: ``python benchmarks/bench_5_isomp_vs_spherical_midpoint.py [--quick] [--out DIR]``.
"""

from __future__ import annotations

import sys

from isoflow.benchmarking import main

if __name__ == "__main__":
    sys.exit(main(["--only", "5", *sys.argv[1:]]))
