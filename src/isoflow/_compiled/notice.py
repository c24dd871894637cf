"""Saying so when a run has to compile its loops (the first run with a kernel on a machine).

numba announces every compilation through its event API (``numba:compile``); loading a
cached result announces nothing. :func:`compile_notice` listens while the first chunk of a run
executes: if a compilation starts, it reports once on the ``isoflow`` logger (and on stderr
when :data:`SHOW` is on, as the command line sets it) what is being compiled, and how long it
took when it ends.
"""

from __future__ import annotations

import logging
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

__all__ = ["SHOW", "compile_notice"]

log = logging.getLogger("isoflow")

#: Also print the notice on stderr (the command line switches this on).
SHOW = False


class _Listener:
    def __init__(self, label: str) -> None:
        self.label = label
        self.started: float | None = None

    def notify(self, event: Any) -> None:
        if self.started is None and event.is_start:
            self.started = time.perf_counter()
            msg = (
                f"compiling the compiled loop for {self.label} (first run with this kernel "
                "here; numba caches it for later runs)..."
            )
            log.info(msg)
            if SHOW:
                print(f"isoflow: {msg}", file=sys.stderr, flush=True)


@contextmanager
def compile_notice(label: str) -> Iterator[None]:
    """Report a compilation that happens inside the block (see the module docstring)."""
    from numba.core import event

    listener = _Listener(label)

    class _Adapter(event.Listener):  # type: ignore[misc]
        def on_start(self, ev: Any) -> None:
            listener.notify(ev)

        def on_end(self, ev: Any) -> None:
            pass

    adapter = _Adapter()
    event.register("numba:compile", adapter)
    try:
        yield
    finally:
        event.unregister("numba:compile", adapter)
        if listener.started is not None:
            msg = f"compiled in {time.perf_counter() - listener.started:.1f} s"
            log.info(msg)
            if SHOW:
                print(f"isoflow: {msg}", file=sys.stderr, flush=True)
