r"""Step data drawn ahead: the noise of a chunk's next piece, drawn while the loop runs this one.

A stochastic step reads *step data* (:class:`~isoflow._compiled.stages.StepDataRequest`): the
Brownian increments of every member and step, drawn in NumPy before the compiled loop runs
(:func:`isoflow.noise.standard_normals`: Philox words and their normal quantiles). For spins
at finite temperature (three normals a spin and step) the draws take a large share of a step:
4.3 ms of a 16 ms step of a thermal 256 x 256 lattice, 6.4 of 12 ms on a chain of 10^5 spins
(benchmarks 18 and 19). A single system's compiled loop runs on one thread, so on a machine
with a core to spare the draws can run beside it.

:func:`pieces` cuts such a chunk of ``n`` steps into a short first piece and at most four
equal ones; the runner draws the first piece's data, then, while the compiled loop (which
releases the GIL) runs piece ``j``, draws piece ``j + 1``'s on one more thread; once the loop
is done, the caller draws the steps still left, from the piece's last step back
(:class:`StepDraws`). While the last piece runs, the helpers draw the first steps of the
run's next chunk, which that chunk takes as its first piece
(:meth:`~isoflow._compiled.runner.CompiledRunner._call_in_pieces`): only the first piece of a
run's first chunk is drawn with nothing running beside it. Measured on a chain of 10^5 spins
with site noise (benchmark 18's, the Cayley update, calls of 20 and 80 steps as parts of one
run): 7.2 and 6.2 ms a step against 8.6 and 6.9 when each chunk drew its own first piece
(IsoMP without noise: 5.3 and 5.1 ms).

A loop that runs on numba threads itself (ensemble members, a long chain's sweeps) leaves no
core to spare while it runs; its chunk's step data is drawn before it by the caller and helpers
together, the numba threads' count of threads in all.

Nothing in the results changes, bit for bit: the step data of step ``k`` is a function of
``(seed, member, k)`` alone, and the driver's arithmetic of a step does not depend on how the
steps of a run are split into calls (:mod:`isoflow._compiled.driver`). The rule
(:func:`how_to_draw`): the run's thread plan gives numba at least two threads and BLAS one
(:mod:`isoflow.threads`; ``threads=1`` turns it off), the chunk has two steps or more, and a
step's data holds at least :data:`DRAW_AHEAD_MIN_VALUES` values; the helpers are the numba
threads but the caller's and the background writer's (a serial run that saves many rows
computes their diagnostics on a thread of its own: on two cores its draws stay inline). A
field that raises in any piece makes the whole chunk count as not done, so the runner redoes
it from its start as it does after a raise in an undivided chunk. The extra thread lives for
one chunk (a thread pool kept across calls would not survive a ``fork`` of the process).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["DRAW_AHEAD_MIN_VALUES", "MAX_PIECES", "StepDraws", "how_to_draw", "pieces"]

Array = NDArray[Any]

#: Smallest step data (values a step, all members) worth drawing on another thread: below it
#: the draws cost less than a thread's start and the calls of more pieces.
DRAW_AHEAD_MIN_VALUES = 2**15
#: Most pieces after the first.
MAX_PIECES = 4


def pieces(nsteps: int) -> list[int]:
    """The steps of each piece of a chunk of ``nsteps``: a first piece of ``max(1, nsteps //
    8)`` steps (its draws are the only ones not hidden), then at most :data:`MAX_PIECES`
    pieces of equal length (the last one shorter).

    Examples
    --------
    >>> pieces(40)
    [5, 9, 9, 9, 8]
    >>> pieces(1)
    [1]
    """
    first = max(1, nsteps // 8)
    rest = nsteps - first
    if rest <= 0:
        return [nsteps]
    size = -(-rest // min(MAX_PIECES, rest))
    out = [first]
    while rest > 0:
        out.append(min(size, rest))
        rest -= out[-1]
    return out


def how_to_draw(
    *, nsteps: int, values_per_step: int, serial_loop: bool, numba_threads: int,
    blas_threads: int,
) -> str:  # fmt: skip
    """How a chunk of ``nsteps`` steps draws its step data (``values_per_step`` is ``0`` while
    unknown, before the run's first draw):

    * ``"inline"``: on the caller's thread before the loop (one step, little data, no thread to
      spare: numba has one thread or BLAS more than one);
    * ``"ahead"``: in pieces beside a serial loop (:func:`pieces`, :class:`StepDraws`);
    * ``"together"``: before a loop that runs on numba threads itself (members, or a chain's
      sweeps), the caller and ``numba_threads - 1`` helpers drawing the steps at once.

    ``numba_threads`` counts the threads the draws may use: the run's numba threads less those
    it keeps busy beside the loop (the background writer of a serial run that saves many
    rows).
    """
    if (
        nsteps < 2
        or values_per_step < DRAW_AHEAD_MIN_VALUES
        or numba_threads < 2
        or blas_threads > 1
    ):
        return "inline"
    return "ahead" if serial_loop else "together"


class StepDraws:
    """The step data of the steps ``k0 + 1 .. k0 + n``, drawn one step at a time from both
    ends: :meth:`help` (on the helper thread) takes steps from the first on, :meth:`result`
    (the caller, once its loop has run the piece before) takes the rest from the last back and
    waits for the helper's step in progress.

    When the draws of a piece take longer than the loop's piece before them (a long spin chain:
    a few memory sweeps an iteration against ``3 N`` normal quantiles a step), the caller's
    core draws the rest instead of waiting: the threads of the run's plan stay busy, and no
    more run than it has. The data is the same whoever draws a step.

    Parameters
    ----------
    draw : callable
        ``draw(k0, nsteps)`` -> the step data ``(nsteps, members, D)`` of the steps ``k0 + 1
        .. k0 + nsteps``.
    k0, n : int
        The steps before the first one drawn, and how many.
    """

    def __init__(self, draw: Callable[[int, int], Array], k0: int, n: int) -> None:
        self._draw = draw
        self._k0 = k0
        self._n = n
        self._lo = 0  # the next step the helper takes
        self._hi = n  # one past the next step the caller takes
        self._stored = 0
        self._error: BaseException | None = None
        self._out: Array | None = None
        self._ready = threading.Condition()

    def _take(self, front: bool) -> int | None:
        with self._ready:
            if self._lo >= self._hi or self._error is not None:
                return None
            if front:
                self._lo += 1
                return self._lo - 1
            self._hi -= 1
            return self._hi

    def _draw_one(self, s: int) -> None:
        """Draw step ``s`` and store it; whatever goes wrong (the draw, the piece's buffer,
        a step of another shape) is handed to :meth:`result`, and the step counts as done
        either way, so that nobody waits for it."""
        try:
            one = self._draw(self._k0 + s, 1)
            with self._ready:
                if self._out is None:
                    self._out = np.empty((self._n, *one.shape[1:]), dtype=one.dtype)
                self._out[s] = one[0]
        except BaseException as exc:
            with self._ready:
                if self._error is None:
                    self._error = exc
        finally:
            with self._ready:
                self._stored += 1
                self._ready.notify_all()

    def cancel(self) -> None:
        """Hand out no more steps (a helper finishes the step it holds): the caller stopped
        before it needs them."""
        with self._ready:
            self._hi = self._lo

    def help(self) -> None:
        """Draw steps from the first on until none is left (the helper thread's part)."""
        while (s := self._take(front=True)) is not None:
            self._draw_one(s)

    def result(self) -> Array:
        """Draw the steps left from the last back, wait for the helper's, and return the
        data ``(n, members, D)``; an error of either thread is raised here."""
        while (s := self._take(front=False)) is not None:
            self._draw_one(s)
        with self._ready:
            self._ready.wait_for(lambda: self._stored >= self._lo + (self._n - self._hi))
            if self._error is not None:
                raise self._error
            assert self._out is not None
            return self._out
