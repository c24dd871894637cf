"""Timing and announcing what numba does during a run: compiling, and loading from its cache.

numba reports two events (``numba.core.event``): ``numba:compiler_lock`` around everything it
does to get machine code for a new signature (load it from the on-disk cache, or compile it),
and ``numba:compile`` around a compilation proper (a cache miss). :func:`compile_clock` listens
to both while a run executes (:func:`isoflow.solve`, a restart):

* the seconds spent inside the compiler lock by the run's thread are the run's
  :attr:`isoflow.SolveStats.compile_time`: compiling (or loading) the user's function, the
  wrapper that calls it from Python, the validation calls of ``B`` before the loop and the
  compiled loops, all of it;
* every compilation is announced on stderr when it starts and when it ends (and on the
  ``isoflow`` logger at INFO), so that a first run that compiles for half a minute does not
  look hung. Loading from the cache is quick and is not announced.

:func:`compile_notice` names what compiles inside a block (the time loop's first chunk names
its compiled loop, which takes several compilations) and announces it once; a compilation
outside any such block is named by its function.

Compilations in other threads (another run, the writer thread) are neither counted nor
announced here. This module imports numba only when a clock starts.
"""

from __future__ import annotations

import logging
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

__all__ = ["SHOW", "CompileClock", "compile_clock", "compile_notice"]

log = logging.getLogger("isoflow")

#: Announce compilations on stderr even in runs with ``progress=False`` (the command line
#: sets it: its runs announce what they compile whatever their progress bars do).
SHOW = False

_current = threading.local()


class _Span:
    """A block named by :func:`compile_notice`: its compilations are announced as one."""

    def __init__(self, label: str) -> None:
        self.label = label
        self.announced = False
        self.seconds = 0.0


class CompileClock:
    """numba's work in one thread while a run executes (see the module docstring).

    Attributes
    ----------
    started : float
        When the clock started (``time.perf_counter()``).
    seconds : float
        Time spent obtaining machine code (compiling or loading from the cache) so far.
    compiled : int
        Compilations announced so far (those of one :func:`compile_notice` block count once).
    """

    def __init__(self, show: bool) -> None:
        self.show = show
        self.started = time.perf_counter()
        self.seconds = 0.0
        self.compiled = 0
        self.thread = threading.get_ident()
        self.spans: list[_Span] = []
        self._lock_depth = 0
        self._lock_started = 0.0
        self._compile_depth = 0
        self._compile_started = 0.0
        self._function = ""

    def _say(self, msg: str) -> None:
        log.info(msg)
        if self.show:
            print(f"isoflow: {msg}", file=sys.stderr, flush=True)

    def _announce(self, what: str) -> None:
        first = self.compiled == 0
        self.compiled += 1
        self._say(
            f"compiling {what}"
            + (
                " (first use of this code here; numba's cache keeps what is compiled with "
                "cache=True for later processes)..."
                if first
                else "..."
            )
        )

    def lock_entered(self) -> None:
        """numba starts to get machine code (a cache load or a compilation)."""
        if self._lock_depth == 0:
            self._lock_started = time.perf_counter()
        self._lock_depth += 1

    def lock_left(self) -> None:
        """numba is done with one request (the outermost one ends the timed interval)."""
        self._lock_depth -= 1
        if self._lock_depth == 0:
            self.seconds += time.perf_counter() - self._lock_started

    def compile_started(self, function: str) -> None:
        """A compilation starts: announce it (in a named block, the block's first one)."""
        self._compile_depth += 1
        if self._compile_depth > 1:
            return
        self._compile_started = time.perf_counter()
        self._function = function
        span = self.spans[-1] if self.spans else None
        if span is None:
            self._announce(function)
        elif not span.announced:
            span.announced = True
            self._announce(span.label)

    def compile_ended(self, failed: bool) -> None:
        """A compilation ends: say how long it took (in a named block: at the block's end)."""
        self._compile_depth -= 1
        if self._compile_depth > 0:
            return
        seconds = time.perf_counter() - self._compile_started
        if self.spans:
            self.spans[-1].seconds += seconds
        elif not failed:
            self._say(f"compiled {self._function} in {seconds:.1f} s")

    def span_ended(self, span: _Span) -> None:
        """A named block ends without an error: say how long its compilations took."""
        if span.announced:
            self._say(f"compiled {span.label} in {span.seconds:.1f} s")

    def close(self) -> None:
        """Count an interval left open by an error (numba ends its events even then)."""
        if self._lock_depth > 0:
            self.seconds += time.perf_counter() - self._lock_started
            self._lock_depth = 0


def _function_name(event: Any) -> str:
    dispatcher = (event.data or {}).get("dispatcher")
    return str(getattr(getattr(dispatcher, "py_func", None), "__name__", "a numba function"))


def _failed(event: Any) -> bool:
    """Whether the compilation that ``event`` ends raised: it added no overload for its
    argument types (numba's ``Event.is_failed`` reads its flag the wrong way round)."""
    data = event.data or {}
    try:
        return tuple(data["args"]) not in data["dispatcher"].overloads
    except (KeyError, TypeError, AttributeError):
        return False


@contextmanager
def compile_clock(show: bool) -> Iterator[CompileClock]:
    """Time and announce numba's work in this thread while the block runs.

    Parameters
    ----------
    show : bool
        Announce compilations on stderr (they are logged at INFO in any case); :data:`SHOW`
        forces it.
    """
    from .threads import check_numba_environment

    check_numba_environment()  # by name, before numba's own import fails on it
    from numba.core import event

    clock = CompileClock(show or SHOW)
    outer = getattr(_current, "clock", None)

    class _Lock(event.Listener):  # type: ignore[misc]
        def on_start(self, ev: Any) -> None:
            if threading.get_ident() == clock.thread:
                clock.lock_entered()

        def on_end(self, ev: Any) -> None:
            if threading.get_ident() == clock.thread:
                clock.lock_left()

    class _Compile(event.Listener):  # type: ignore[misc]
        def on_start(self, ev: Any) -> None:
            if threading.get_ident() == clock.thread:
                clock.compile_started(_function_name(ev))

        def on_end(self, ev: Any) -> None:
            if threading.get_ident() == clock.thread:
                clock.compile_ended(_failed(ev))

    listeners = [("numba:compiler_lock", _Lock()), ("numba:compile", _Compile())]
    for kind, listener in listeners:
        event.register(kind, listener)
    _current.clock = clock
    try:
        yield clock
    finally:
        for kind, listener in listeners:
            event.unregister(kind, listener)
        _current.clock = outer
        clock.close()


@contextmanager
def compile_notice(label: str) -> Iterator[None]:
    """Announce what compiles inside the block as ``label``, once, with the time it took
    (in the current clock; nothing without one)."""
    clock: CompileClock | None = getattr(_current, "clock", None)
    if clock is None:
        yield
        return
    span = _Span(label)
    clock.spans.append(span)
    try:
        yield
    finally:
        clock.spans.pop()
    clock.span_ended(span)
