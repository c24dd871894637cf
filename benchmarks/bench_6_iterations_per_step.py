"""Benchmark 6 of the suite (see :mod:`isoflow.benchmarking`): iterations per step.

Usage: ``python benchmarks/bench_6_iterations_per_step.py [--quick] [--out DIR]``.
"""

from __future__ import annotations

import sys

from isoflow.benchmarking import main

if __name__ == "__main__":
    sys.exit(main(["--only", "6", *sys.argv[1:]]))
