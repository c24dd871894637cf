"""What the commands share: argument types, thread options, output tables, one-line errors.

User mistakes end with a one-line ``isoflow: error: ...`` on stderr and exit status 1
(:func:`run_command`; argparse's own errors exit with 2), never a traceback; ``ISOFLOW_DEBUG=1``
shows the traceback anyway.
"""

from __future__ import annotations

import argparse
import math
import os
import signal
import sys
import warnings
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from .. import registry
from .._errors import IsoflowError

__all__ = [
    "UserError",
    "add_thread_options",
    "anderson_memory",
    "announce_compiles",
    "finite_float",
    "positive_float",
    "positive_int",
    "progress",
    "run_command",
    "summary_lines",
    "sweep_task_note",
    "table",
    "threads_text",
    "warnings_as_lines",
]


class UserError(IsoflowError):
    """A mistake on the command line or in a configuration file."""


# ---- argument types ----------------------------------------------------------------------------


def finite_float(text: str) -> float:
    """A finite number (an argparse type)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be finite: {text!r}")
    return value


def positive_float(text: str) -> float:
    """A finite positive number (an argparse type)."""
    value = finite_float(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be positive: {text!r}")
    return value


def positive_int(text: str) -> int:
    """An integer >= 1 (an argparse type)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1: {text!r}")
    return value


def anderson_memory(text: str) -> int:
    """An Anderson memory, 0 to :data:`isoflow.registry.ANDERSON_MAX` (an argparse type)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if not 0 <= value <= registry.ANDERSON_MAX:
        raise argparse.ArgumentTypeError(f"must be in 0..{registry.ANDERSON_MAX}: {text!r}")
    return value


def add_thread_options(parser: argparse.ArgumentParser, default: Any = argparse.SUPPRESS) -> None:
    """``--threads`` and ``--blas-threads`` (on the main parser and on every command that
    computes; a command's own flags leave the main parser's value alone unless given)."""
    parser.add_argument(
        "--threads",
        type=positive_int,
        default=default,
        metavar="K",
        help=(
            "cores a run may use: numba threads when its compiled loop runs ensemble members "
            "in parallel, else BLAS threads (default: 1 BLAS thread, numba on every core; "
            "see iso.threads)"
        ),
    )
    parser.add_argument(
        "--blas-threads",
        type=positive_int,
        default=default,
        metavar="K",
        help="BLAS/OpenMP threads (default 1); numba gets the cores they leave",
    )


# ---- running and printing ----------------------------------------------------------------------


def announce_compiles() -> None:
    """Say on stderr when a run compiles, also in runs without a progress bar (``--quiet``)."""
    from .. import _compile_clock

    _compile_clock.SHOW = True


def progress(args: argparse.Namespace) -> bool | None:
    """The ``progress`` argument of a run for ``--quiet``: off, or the library's default."""
    return False if args.quiet else None


def table(rows: Sequence[tuple[str, str]]) -> list[str]:
    """``name  value`` lines, indented two spaces, the values aligned after the longest name."""
    width = max((len(name) for name, _ in rows), default=0)
    return [f"  {name:<{width}}  {value}" for name, value in rows]


def threads_text(threads: dict[str, Any]) -> str:
    """``SolveStats.threads`` in words: ``"1 BLAS, 2 numba (2 cores)"``."""
    return (
        f"{threads.get('blas', '?')} BLAS, {threads.get('numba', '?')} numba "
        f"({threads.get('cores', '?')} cores)"
    )


def summary_lines(title: str, sol: Any, path: str | None = None) -> list[str]:
    """What ``isoflow run`` prints after a run: steps, time, threads, drifts, status, file."""
    d = sol.diagnostics.summary() if sol.diagnostics is not None else {}
    st = sol.stats
    rows = [
        (
            "steps",
            f"{st.n_steps} of {sol.n_steps}"
            + (f" (this call: {st.first_step + 1} to {st.n_steps})" if st.first_step else ""),
        ),
        (
            "wall time",
            f"{st.wall_time:.2f} s"
            + (f" (compiling {st.compile_time:.1f} s)" if st.compile_time > 0.5 else ""),
        ),
        ("runner", st.runner),
        ("threads", threads_text(st.threads)),
        ("iterations per step", f"mean {st.iterations_mean:.2f}, max {st.iterations_max}"),
        *((k, f"{v:.3e}") for k, v in d.items()),
        ("status", sol.message),
    ]
    note = None
    if sol.diagnostics is not None and sol.diagnostics.forced_or_dissipative:
        note = "forced or dissipative: Casimirs and energy change by design (drifts are changes)"
    elif sol.diagnostics is not None and sol.diagnostics.energy_changes:
        note = "noise or damping: the energy may change by design (its drift is a change)"
    if note is not None:
        rows.insert(len(rows) - len(d) - 1, ("note", note))  # just before the drifts
    if path is not None:
        rows.append(("file", path))
    return [title, *table(rows)]


def sweep_task_note(path: str, config: dict[str, Any]) -> str | None:
    """For a sweep's task file: how to continue it (running its sweep again), else ``None``."""
    mark = config.get("sweep")
    if not isinstance(mark, dict):
        return None
    directory = Path(path).resolve().parent.parent
    return (
        f"task {mark.get('task')} of the sweep in {directory}: run the sweep again to resume "
        f"it (isoflow sweep SWEEP.toml --out {directory}), not isoflow run --resume"
    )


@contextmanager
def warnings_as_lines() -> Iterator[None]:
    """Show warnings as one ``isoflow: warning: ...`` line each on stderr."""

    def show(message: Any, category: Any, *args: Any, **kwargs: Any) -> None:
        print(f"isoflow: warning: {' '.join(str(message).split())}", file=sys.stderr)

    with warnings.catch_warnings():
        warnings.showwarning = show
        yield


def run_command(args: argparse.Namespace) -> int:
    """Run the parsed command (within the thread limits of a command that computes); its exit
    status, or 1 after a one-line error for a user's mistake (130 when interrupted)."""
    from .. import _compile_clock

    announced = _compile_clock.SHOW  # the commands announce compilations; restored after
    terminated: list[int] = []
    previous = _on_sigterm(terminated)
    try:
        from ..threads import check_numba_environment

        check_numba_environment()
        if not args.computes:
            return int(args.handler(args))
        from ..threads import thread_limits

        if args.threads is not None and args.blas_threads is not None:
            raise UserError("give --threads or --blas-threads, not both")
        with thread_limits(blas=args.blas_threads, threads=args.threads):
            return int(args.handler(args))
    except BrokenPipeError:  # the reader went away (isoflow list | head): stop quietly
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 1
    except (IsoflowError, OSError, ValueError, TypeError, MemoryError) as exc:
        if os.environ.get("ISOFLOW_DEBUG"):
            raise
        msg = " ".join(str(exc).split()) or type(exc).__name__
        if isinstance(exc, MemoryError):
            msg = f"out of memory: {msg} (a smaller model, or a machine with more memory)"
        print(f"isoflow: error: {msg}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        if terminated:
            print("isoflow: terminated (SIGTERM)", file=sys.stderr)
            return 143
        print("isoflow: interrupted", file=sys.stderr)
        return 130
    finally:
        _compile_clock.SHOW = announced
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


def _on_sigterm(terminated: list[int]) -> Any:
    """Make SIGTERM (a batch system's time limit, ``kill``) stop a command as Ctrl-C does: the
    run checkpoints and closes its file (resumable, no stale lock), instead of dying at once.
    Returns the previous handler (``None`` outside the main thread, where none is set)."""

    def stop(signum: int, frame: Any) -> None:
        terminated.append(signum)
        handler = signal.getsignal(signal.SIGINT)  # the run's, holding it back mid-chunk
        if callable(handler):
            handler(signal.SIGINT, frame)
        else:
            raise KeyboardInterrupt

    try:
        return signal.signal(signal.SIGTERM, stop)
    except (ValueError, OSError):  # not the main thread
        return None
