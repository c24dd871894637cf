"""Benchmark 4 of the suite (see :mod:`isoflow.benchmarking`): spin chain bandwidth.

Usage: ``python benchmarks/bench_4_spin_chain_bandwidth.py [--quick] [--out DIR]``.
"""

from __future__ import annotations

import sys

from isoflow.benchmarking import main

if __name__ == "__main__":
    sys.exit(main(["--only", "4", *sys.argv[1:]]))
