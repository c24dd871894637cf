"""Which steps of a run are saved: :class:`SaveGrid`, the one statement of the rule.

A run of ``k_final`` steps saves the state after step ``k`` when ``k`` is a multiple of
``save_every`` or ``k == k_final`` (the initial state, step 0, is saved by the time loop when a
run starts). The time loop, the runners, the compiled driver and the readers of result files
all count saved rows with this class.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["SaveGrid"]


@dataclass(frozen=True)
class SaveGrid:
    """The save points of a run: multiples of ``every`` and the last step ``k_final``.

    Attributes
    ----------
    every : int
        ``save_every`` (positive).
    k_final : int
        The run's last step.
    """

    every: int
    k_final: int

    def is_save(self, k: int) -> bool:
        """Whether the state after step ``k`` is saved."""
        return k % self.every == 0 or k == self.k_final

    def count(self, k0: int, k1: int) -> int:
        """Number of save points ``k`` in ``(k0, k1]``."""
        if k1 <= k0:
            return 0
        c = k1 // self.every - k0 // self.every
        if k0 < self.k_final <= k1 and self.k_final % self.every:
            c += 1
        return c

    def points(self, k0: int, k1: int) -> NDArray[np.int64]:
        """The save points in ``(k0, k1]``, in order."""
        first = (k0 // self.every + 1) * self.every
        ks = list(range(first, k1 + 1, self.every))
        if k0 < self.k_final <= k1 and self.k_final % self.every:
            ks.append(self.k_final)
        return np.asarray(ks, dtype=np.int64)

    def saved_steps(self) -> NDArray[np.int64]:
        """Every saved step of a whole run, the start (step 0) included."""
        return np.concatenate([[0], self.points(0, self.k_final)]).astype(np.int64)

    def rows(self, fresh: bool) -> int:
        """Rows of a whole run: the save points, and the initial state when ``fresh``."""
        return self.count(0, self.k_final) + (1 if fresh else 0)

    def steps_for_rows(self, k0: int, rows: int) -> int:
        """Steps from ``k0`` until ``rows`` save points have passed (at least 1, capped at
        ``k_final``)."""
        nxt = (k0 // self.every + rows) * self.every
        return max(min(nxt, self.k_final) - k0, 1)

    def end_at_save(self, k0: int, nsteps: int) -> int:
        """``nsteps`` shortened (or lengthened to the next save point) so that a chunk from
        ``k0`` ends at a save point."""
        end = k0 + nsteps
        if self.is_save(end):
            return nsteps
        last = (end // self.every) * self.every
        if last > k0:
            return last - k0
        return self.next_after(k0) - k0

    def next_after(self, k0: int) -> int:
        """The first save point after ``k0``."""
        return min((k0 // self.every + 1) * self.every, self.k_final)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {"save_every": self.every, "k_final": self.k_final}
