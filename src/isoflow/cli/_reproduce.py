"""``isoflow reproduce``: the paper's experiments, their figures and JSON summaries."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from .. import registry
from ._common import UserError, add_thread_options, announce_compiles, progress

__all__ = ["add_parser", "handle"]


def add_parser(sub: Any) -> None:
    """Declare ``isoflow reproduce`` on the subparsers ``sub``."""
    experiments = tuple(registry.EXPERIMENTS)
    rep = sub.add_parser(
        "reproduce",
        help="run the paper's experiments: figures and JSON summaries",
        description=(
            "Run experiments of the paper (Section 3, corrected conventions) and write a PNG and "
            "a PDF figure and a JSON summary for each (replacing those of an earlier run). "
            "Experiments: " + ", ".join(experiments)
        ),
    )
    rep.add_argument(
        "experiment",
        choices=("all", *experiments),
        metavar="EXPERIMENT",
        help="'all' or one of: " + ", ".join(experiments),
    )
    rep.add_argument("--out", default="results", help="output directory (default results/)")
    rep.add_argument("--quick", action="store_true", help="reduced versions (CI, a first look)")
    rep.add_argument("--no-pdf", action="store_true", help="PNG only")
    rep.add_argument("--quiet", action="store_true", help="no progress bars")
    add_thread_options(rep)
    rep.set_defaults(handler=handle, computes=True)


def handle(args: argparse.Namespace) -> int:
    """Run the experiments, writing their figures and JSON summaries into ``--out``."""
    from ..experiments import run_experiment

    names = list(registry.EXPERIMENTS) if args.experiment == "all" else [args.experiment]
    out = Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"cannot create output directory {out}: {exc.strerror}") from None
    announce_compiles()
    start = time.perf_counter()
    for name in names:
        t = time.perf_counter()
        files = run_experiment(
            name, out, quick=args.quick, pdf=not args.no_pdf, progress=progress(args)
        )
        print(f"{name:<24} {time.perf_counter() - t:7.1f} s  " + " ".join(str(f) for f in files))
    print(f"{'total':<24} {time.perf_counter() - start:7.1f} s")
    return 0
