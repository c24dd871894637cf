r"""Status lines of a long run: where it stands, its speed and when it will end.

A run left for hours or days (``isoflow run euler-sphere --N 1024 ...`` under ``nohup``, in a
batch job, or in a terminal) writes one line to stderr every ``status_every`` seconds of wall
time, for example::

    isoflow: step 1200 of 50000 (2.4 %), t = 12, 3.21 steps/s, ends about Thu 27 Nov 14:05 UTC
    (in 4 h 13 min)

(one line; wrapped here).
The speed is the mean over the run so far, leaving out its first chunk (which may compile);
the end is projected at that speed from now. A line is a whole line (a log file stays
readable), written through tqdm so that a progress bar on a terminal stays intact.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, field
from datetime import datetime, timedelta
from typing import TextIO

__all__ = ["StatusLines", "duration_text", "status_line"]


def duration_text(seconds: float) -> str:
    """``seconds`` in words a person reads at a glance: ``"42 s"``, ``"7 min"``,
    ``"4 h 13 min"``, ``"3 d 2 h"``."""
    s = max(0.0, float(seconds))
    if s < 90:
        return f"{s:.0f} s"
    minutes = round(s / 60)
    if minutes < 90:
        return f"{minutes} min"
    hours, minutes = divmod(minutes, 60)
    if hours < 48:
        return f"{hours} h {minutes} min"
    days, hours = divmod(hours, 24)
    return f"{days} d {hours} h"


def status_line(
    k: int, n: int, t: float, rate: float | None, now: datetime, prefix: str = "isoflow"
) -> str:
    r"""One status line: step ``k`` of ``n`` at time ``t``, at ``rate`` steps per second.

    Parameters
    ----------
    k, n : int
        Steps done and the run's steps.
    t : float
        Simulated time at step ``k``.
    rate : float or None
        Steps per wall-clock second; ``None`` (not measured yet) leaves out the speed and the
        projected end.
    now : datetime
        The wall-clock time of the line, timezone-aware (the projected end is ``now +
        (n - k) / rate``, written in ``now``'s timezone).
    prefix : str
        The line's first word.
    """
    parts = [f"{prefix}: step {k} of {n} ({100.0 * k / max(n, 1):.1f} %)", f"t = {t:.6g}"]
    if rate is not None and rate > 0 and math.isfinite(rate):
        parts.append(f"{rate:.3g} steps/s")
        left = (n - k) / rate
        if left > 0:
            end = now + timedelta(seconds=left)
            parts.append(
                f"ends about {end.strftime('%a %d %b %H:%M %Z').strip()} (in {duration_text(left)})"
            )
    return ", ".join(parts)


@dataclass
class StatusLines:
    """Writes :func:`status_line` every :attr:`every` seconds while a run advances.

    Parameters
    ----------
    every : float or None
        Seconds of wall time between lines; ``None`` writes none.
    n : int
        The run's steps.
    t0, dt : float
        The run's time grid (``t = t0 + k dt``).
    stream : text stream or None
        Where the lines go (``None``: ``sys.stderr`` at the time of writing).
    """

    every: float | None
    n: int
    t0: float
    dt: float
    stream: TextIO | None = None
    _started: float = field(default_factory=time.monotonic)
    _last: float = field(default_factory=time.monotonic)
    _base: tuple[int, float] | None = None  # (k, clock) after the first chunk
    written: int = 0

    def after_chunk(self, k: int) -> None:
        """The run stands at step ``k`` after a chunk: write a line if one is due."""
        if self.every is None:
            return
        now = time.monotonic()
        if self._base is None:  # the first chunk may compile: the speed is measured after it
            self._base = (k, now)
            return
        if now - self._last < self.every or k >= self.n:
            return
        self._last = now
        k_base, t_base = self._base
        rate = (k - k_base) / (now - t_base) if now > t_base and k > k_base else None
        line = status_line(k, self.n, self.t0 + k * self.dt, rate, datetime.now().astimezone())
        from tqdm.auto import tqdm

        tqdm.write(line, file=self.stream if self.stream is not None else sys.stderr)
        self.written += 1
