"""Benchmark 3 of the suite (see :mod:`isoflow.benchmarking`): large dense.

Usage: ``python benchmarks/bench_3_large_dense.py [--quick] [--out DIR]``.
"""

from __future__ import annotations

import sys

from isoflow.benchmarking import main

if __name__ == "__main__":
    sys.exit(main(["--only", "3", *sys.argv[1:]]))
