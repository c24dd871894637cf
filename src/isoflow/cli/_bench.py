"""``isoflow bench``: the benchmark suite of a source checkout (``benchmarks/run_all.py``)."""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path
from typing import Any

from ._common import UserError

__all__ = ["add_parser", "handle", "source_tree"]


def add_parser(sub: Any) -> None:
    """Declare ``isoflow bench`` on the subparsers ``sub``."""
    bench = sub.add_parser(
        "bench",
        help="run the benchmark suite of a source checkout (ratios to baselines; JSON + table)",
        description=(
            "Run benchmarks/run_all.py of the source tree this isoflow is installed from "
            "(pip install -e .). The benchmarks are not part of the installed package."
        ),
    )
    bench.add_argument("--out", default="benchmark-results", help="output directory")
    bench.add_argument("--quick", action="store_true", help="smaller sizes (about a minute)")
    bench.add_argument(
        "--only", metavar="K,...", help="benchmark numbers (default: all; checked by the suite)"
    )
    bench.add_argument("--figure", metavar="PNG", help="write the spin-chain-cost figure here")
    bench.set_defaults(handler=handle, computes=False)


def source_tree() -> Path | None:
    """The repository this isoflow is installed from (an editable install), if any."""
    root = Path(__file__).resolve().parents[3]
    if (root / "benchmarks" / "run_all.py").is_file() and (root / "pyproject.toml").is_file():
        return root
    return None


def handle(args: argparse.Namespace) -> int:
    """Run the benchmark suite of the source tree; its exit status."""
    root = source_tree()
    if root is None:
        raise UserError(
            "the benchmarks live in the source repository, not in the installed package: clone "
            "it, install it with pip install -e . and run isoflow bench (or python "
            "benchmarks/run_all.py) there"
        )
    cmd = [sys.executable, str(root / "benchmarks" / "run_all.py"), "--out", args.out]
    if args.quick:
        cmd.append("--quick")
    if args.only:
        cmd += ["--only", args.only]
    if args.figure:
        cmd += ["--figure", args.figure]
    return subprocess.run(cmd, check=False).returncode
