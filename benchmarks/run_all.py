"""Run the isoflow benchmark suite (issue 6) and write JSON + a markdown table.

Usage (from the repository root)::

    python benchmarks/run_all.py --out benchmarks/results \
        --figure benchmarks/results/spin_chain_cost.png
    python benchmarks/run_all.py --quick --only 1,2      # a subset, smaller sizes

Equivalent to ``isoflow bench`` / ``python -m isoflow.benchmarking``; the benchmarks
themselves live in :mod:`isoflow.benchmarking` so that the installed command can run them.
Not part of the test suite.
"""

from __future__ import annotations

import sys

from isoflow.benchmarking import main

if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
