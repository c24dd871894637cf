"""Run the isoflow benchmark suite and write JSON + a markdown table.

Usage (from the repository root, with isoflow installed, e.g. ``pip install -e .``)::

    python benchmarks/run_all.py --out benchmarks/results \\
        --figure benchmarks/results/spin_chain_cost.png
    python benchmarks/run_all.py --quick --only 1,2      # a subset, smaller sizes
    isoflow bench --quick --only 1,2                     # the same, through the command line

The benchmarks are the ``bench_<k>_*.py`` files of this directory (see ``suite.py``). Not part
of the test suite: the ratios are measured, reported and compared with their targets, never
asserted.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

# numba's cache: the checkout's own, emptied when the compiled sources changed (numba alone
# would load a loop compiled before an inlined block changed), set before numba is imported
if "NUMBA_CACHE_DIR" not in os.environ:
    from isoflow._numba_cache import refresh

    os.environ["NUMBA_CACHE_DIR"] = str(Path(__file__).resolve().parents[1] / ".numba_cache")
    refresh(Path(os.environ["NUMBA_CACHE_DIR"]))

import suite


def _numbers(text: str) -> list[int]:
    try:
        values = [int(k) for k in text.split(",") if k.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"not a comma-separated list of benchmark numbers: {text!r}"
        ) from None
    if not values:
        raise argparse.ArgumentTypeError(f"no benchmark numbers in {text!r}")
    return values


def main(argv: Sequence[str] | None = None) -> int:
    """Command line of the suite; returns the exit status (2 for a bad command line)."""
    benchmarks = suite.load()
    known = ", ".join(map(str, benchmarks))
    ap = argparse.ArgumentParser(
        prog="isoflow bench",
        description="isoflow benchmark suite: speed as ratios to baselines timed in the same run. "
        + " ".join(f"({k}) {b.title}." for k, b in benchmarks.items()),
    )
    ap.add_argument("--out", default="benchmark-results", help="output directory")
    ap.add_argument("--quick", action="store_true", help="smaller sizes (about a minute)")
    ap.add_argument("--only", type=_numbers, metavar="K,...", help=f"benchmarks among {known}")
    drawn = [k for k, b in benchmarks.items() if b.figure is not None]
    ap.add_argument(
        "--figure",
        default=None,
        metavar="PNG",
        help=f"write the figure of benchmark {', '.join(map(str, drawn))} here",
    )
    args = ap.parse_args(argv)
    unknown = sorted(set(args.only or ()) - set(benchmarks))
    if unknown:
        ap.error(f"no benchmark {', '.join(map(str, unknown))} (benchmarks: {known})")
    selected = args.only or list(benchmarks)

    start = time.perf_counter()
    results, failed = [], []
    for k in sorted(set(selected)):
        t = time.perf_counter()
        try:
            rows = benchmarks[k].run(args.quick)
        except Exception as exc:  # report it and go on with the other benchmarks
            failed.append(k)
            message = f"{type(exc).__name__}: {exc}"
            print(f"benchmark {k} failed: {message}", file=sys.stderr, flush=True)
            results.append(suite.record(k, f"{benchmarks[k].title} (failed)", error=message,
                                        metric="error", value=float("nan"), target="-",
                                        met=False))  # fmt: skip
            continue
        draw = benchmarks[k].figure
        if args.figure and draw is not None:
            path = Path(args.figure)
            if len(drawn) > 1:
                path = path.with_name(f"{path.stem}-{k}{path.suffix}")
            path.parent.mkdir(parents=True, exist_ok=True)
            draw(rows, path)
        results.extend(rows)
        print(f"benchmark {k}: {time.perf_counter() - t:.1f} s", flush=True)
    report = {"machine": suite.machine(), "results": results,
              "wall_time": time.perf_counter() - start}  # fmt: skip
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "benchmarks.json").write_text(json.dumps(suite.jsonable(report), indent=2) + "\n")
    table = suite.to_markdown(report)
    (out / "benchmarks.md").write_text(table)
    print(table)
    if failed:
        print(f"benchmarks that failed: {', '.join(map(str, failed))}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
