"""The ``isoflow`` command line: it parses and prints; the work is library calls.

Commands, one module each (its parser declared next to its handler):

* ``isoflow demo``: the paper's so(10) rigid body with IsoMP, printing invariant drifts;
* ``isoflow run MODEL ... --out FILE`` (or ``--config run.toml``): a model of
  :mod:`isoflow.registry` (built in, registered by an installed package, or your own
  ``--model package.module:factory``) streamed to an HDF5 result file; ``isoflow run --resume
  FILE`` continues a stopped or killed run bit for bit;
* ``isoflow info FILE``: what a result file holds, its parameters and invariant drifts (or a
  sweep directory: its tasks, failed members and worst drifts);
* ``isoflow sweep SWEEP.toml --out DIR``: a sweep of :mod:`isoflow.sweep` on dask.distributed;
* ``isoflow plot FILE --out PNG``: invariants and state components from a result file;
* ``isoflow reproduce NAME|all --out DIR [--quick]``: the paper's experiments, figures and JSON;
* ``isoflow list [models|methods|solvers|experiments]``: the names the other commands take;
* ``isoflow bench ...``: the benchmark suite of a source checkout (``benchmarks/run_all.py``).

User mistakes end with a one-line ``isoflow: error: ...`` on stderr and a non-zero exit status
(2 for a bad command line, 1 otherwise), never a traceback. Set ``ISOFLOW_DEBUG=1`` to see the
traceback of an error anyway. Modules beyond the numerical core (HDF5, matplotlib, numba) are
imported only by the commands that use them, after the command line has been parsed.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import NoReturn

from .._version import __version__
from . import _bench, _demo, _info, _list, _plot, _reproduce, _run, _sweep
from ._common import add_thread_options, run_command

__all__ = ["main"]

#: The commands, in the order ``isoflow --help`` lists them.
_COMMANDS = (_demo, _run, _info, _sweep, _plot, _reproduce, _list, _bench)


class _Parser(argparse.ArgumentParser):
    """argparse's parser with a one-line error (the usage block stays with ``--help``); the
    commands' parsers are of this class too (``add_subparsers`` takes the parent's)."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    """The parser of the ``isoflow`` command: its options and every command's."""
    parser = _Parser(
        prog="isoflow",
        description="Structure-preserving integration of isospectral flows (IsoMP).",
    )
    parser.add_argument("--version", action="version", version=f"isoflow {__version__}")
    add_thread_options(parser, default=None)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for command in _COMMANDS:
        command.add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``isoflow`` command; returns the exit status.

    Parameters
    ----------
    argv : sequence of str, optional
        The arguments after the program name (default: ``sys.argv[1:]``).

    Returns
    -------
    int
        The exit status (0 on success).
    """
    args = build_parser().parse_args(list(sys.argv[1:] if argv is None else argv))
    return run_command(args)
