"""``isoflow plot``: invariants and state components of a result file, as an image file."""

from __future__ import annotations

import argparse
from typing import Any

__all__ = ["add_parser", "handle"]


def add_parser(sub: Any) -> None:
    """Declare ``isoflow plot`` on the subparsers ``sub``."""
    plot = sub.add_parser(
        "plot",
        help="plot invariants and states from a result file",
        description=(
            "Draw a result file: the variation of the Casimirs, of the Hamiltonian (or the "
            "Lyapunov function; no panel when the problem has neither), of the problem's "
            "invariants (or the distance to the space), and up to six state components that "
            "move, against time; a forced or dissipative sphere run adds its energy and "
            "enstrophy budgets, energy and transfer spectra and, for QG, the zonal-mean wind. "
            "Writes PNG, PDF or SVG by the suffix of --out. An ensemble's figure shows one "
            "member (--member, default 0)."
        ),
    )
    plot.add_argument("file", help="an isoflow result file (HDF5)")
    plot.add_argument("--out", required=True, help="image file (.png, .pdf, .svg)")
    plot.add_argument("--force", action="store_true", help="replace an existing --out file")
    plot.add_argument(
        "--member", type=int, default=None, metavar="K",
        help="for an ensemble (a sweep's task file too): the member drawn (flat index; default 0)",
    )  # fmt: skip
    plot.set_defaults(handler=handle, computes=False)


def handle(args: argparse.Namespace) -> int:
    """Draw the result file into the image file ``--out``."""
    from .. import io, plotting

    run = io.load(args.file)
    fig = plotting.plot_run(run, member=args.member)
    plotting.save(fig, args.out, force=args.force)
    print(f"wrote {args.out}")
    return 0
