"""``isoflow sweep``: a sweep file's members run on dask.distributed (:func:`isoflow.sweep.run`)."""

from __future__ import annotations

import argparse
from typing import Any

from ._common import positive_float, positive_int, warnings_as_lines

__all__ = ["add_parser", "handle"]


def add_parser(sub: Any) -> None:
    """Declare ``isoflow sweep`` on the subparsers ``sub``."""
    sw = sub.add_parser(
        "sweep",
        help="run a sweep (sweep.toml: a model, a method, a table of members) on dask",
        description=(
            "Run the members of a sweep file as batched ensembles in dask workers, each task "
            "streamed to DIR/tasks/<id>.h5; run it again to resume. Needs isoflow[sweep]. "
            "Exit status 0: every member finished; 1: a member failed, a task raised, or an "
            "error (one line); 2: a bad command line."
        ),
    )
    sw.add_argument("file", help="the sweep file (TOML; see the user guide's page on sweeps)")
    sw.add_argument("--out", metavar="DIR", help="the sweep directory (default: the file's out)")
    where = sw.add_mutually_exclusive_group()
    where.add_argument(
        "--workers",
        type=positive_int,
        metavar="K",
        help="local worker processes (default and most: the cores available)",
    )
    where.add_argument("--scheduler", metavar="ADDR", help="a running dask scheduler to use")
    sw.add_argument(
        "--connect-timeout",
        type=positive_float,
        default=30.0,
        metavar="SECONDS",
        help="how long to wait for --scheduler to answer (default 30 s)",
    )
    sw.add_argument(
        "--retries", type=int, default=2, metavar="R", help="worker deaths a task survives (2)"
    )
    sw.add_argument("--quiet", action="store_true", help="no progress")
    sw.set_defaults(handler=handle, computes=False)


def handle(args: argparse.Namespace) -> int:
    """Run (or resume) the sweep; exit status 0 when every member finished."""
    from ..sweep import read_spec, run
    from ..sweep.spec import require_extra

    require_extra("dask", "distributed", "xarray")
    spec = read_spec(args.file)
    with warnings_as_lines():
        result = run(
            spec,
            args.out,
            scheduler=args.scheduler,
            workers=args.workers,
            retries=args.retries,
            connect_timeout=args.connect_timeout,
            progress=not args.quiet,
        )
    print(result)
    for tid, msg in result.redone.items():
        print(f"  task {tid} redone: {msg}")
    for tid, msg in result.errors.items():
        print(f"  task {tid} raised: {msg}")
    if result.failed_members:
        shown = ", ".join(map(str, result.failed_members[:20]))
        more = len(result.failed_members) - 20
        shown += f" and {more} more" if more > 0 else ""
        print(f"  failed members: {shown} (isoflow info {result.path})")
    return 0 if result.success else 1
