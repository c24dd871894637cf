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
releases the GIL) runs piece ``j``, draws piece ``j + 1``'s on one more thread. Only the first
piece's draws (about an eighth) stay on the critical path.

Nothing in the results changes, bit for bit: the step data of step ``k`` is a function of
``(seed, member, k)`` alone, and the driver's arithmetic of a step does not depend on how the
steps of a run are split into calls (:mod:`isoflow._compiled.driver`). The rule
(:func:`draws_ahead`): the run's thread plan gives numba at least two threads and BLAS one
(:mod:`isoflow.threads`; ``threads=1`` turns it off), the loop is serial (one unit, sweeps not
cut over threads), and a step's data holds at least :data:`DRAW_AHEAD_MIN_VALUES` values. A
field that raises in any piece makes the whole chunk count as not done, so the runner redoes
it from its start as it does after a raise in an undivided chunk. The extra thread lives for
one chunk (a thread pool kept across calls would not survive a ``fork`` of the process).
"""

from __future__ import annotations

__all__ = ["DRAW_AHEAD_MIN_VALUES", "MAX_PIECES", "draws_ahead", "pieces"]

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


def draws_ahead(
    *, nsteps: int, values_per_step: int, serial_loop: bool, numba_threads: int,
    blas_threads: int,
) -> bool:  # fmt: skip
    """Whether a chunk of ``nsteps`` steps draws its step data ahead (the module docstring's
    rule); ``values_per_step`` is ``0`` while unknown (before the run's first draw)."""
    return (
        nsteps >= 2
        and values_per_step >= DRAW_AHEAD_MIN_VALUES
        and serial_loop
        and numba_threads >= 2
        and blas_threads <= 1
    )
