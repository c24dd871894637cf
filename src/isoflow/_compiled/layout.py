"""The Python side of a layout: its record, how states map to its units and back.

Each layout module (:mod:`.dense`, :mod:`.particles`, :mod:`.vortices`, :mod:`.spin_chain`,
:mod:`.lanes`) has a builder that returns a :class:`Layout` for the runs it takes;
:func:`isoflow._compiled.runner.compiled_runner` asks them in turn.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from . import blocks

__all__ = ["Layout", "member_layout"]

Array = NDArray[Any]
Map = Callable[[Array], Array]


@dataclass(frozen=True)
class Layout:
    """How a run's states are laid out for the compiled loops.

    Attributes
    ----------
    name : str
        For messages (``"dense so(10) (written-out products)"``, ...).
    record : NamedTuple
        The layout record the compiled blocks dispatch on (:mod:`.blocks`).
    to_units : callable
        ``(M, *core)`` user states -> a new C-contiguous ``(U, S)`` array of units.
    from_units : callable
        ``(..., U, S)`` -> ``(..., M, *core)`` states in the user's layout (projected onto the
        space where the layout is a change of frame).
    offsets_from_units : callable
        The same for stage offsets (projected onto the stage space).
    rows_from_flat : callable
        Saved rows ``(R, M, S1)`` (one member's flat state each) -> ``(R, M, *core)``.
    lanes : int
        Members per unit.
    identity : bool
        Whether a unit is one member in the user's layout (a reshape, no copy or change of
        frame): the driver then writes saved rows straight into the caller's buffer.
    field : (f, args) or None
        The field to call instead of the kernel's (the entrywise one inside a frame).
    restart_at_saves : bool
        The layout's change of variables is not exact in floating point (a frame): the state
        and the offsets are mapped to the user's layout and back at every save point, so that
        a run restarted from a saved state (a checkpoint) continues it bit for bit.
    threaded : bool
        A unit's work runs over numba threads (a long spin chain cut into chunks, the
        products and passes of a large complex matrix): the loop of one unit is not serial,
        and the run's cores go to numba (:mod:`isoflow.threads`).
    serial_by_default : bool
        A ``threaded`` unit runs on one numba thread unless the run asks for more
        (``threads=k``, ``{"numba": m}`` or a :func:`~isoflow.threads.thread_limits` block):
        its pieces are split among the threads in equal shares, so a thread that shares its
        core with another process holds up every pass (measured in the threads guide).
    """

    name: str
    record: Any
    to_units: Map
    from_units: Map
    offsets_from_units: Map
    rows_from_flat: Map
    lanes: int = 1
    identity: bool = True
    field: tuple[Any, tuple[Any, ...]] | None = None
    restart_at_saves: bool = False
    threaded: bool = False
    serial_by_default: bool = False

    @property
    def blocks(self) -> frozenset[str]:
        """The blocks its record provides."""
        return blocks.provided(type(self.record))

    def units(self, members: int) -> int:
        """Units holding ``members`` members."""
        return -(-members // self.lanes)


def member_layout(name: str, record: Any, core: tuple[int, ...], dtype: Any) -> Layout:
    """A layout whose unit is one member in the user's layout (a reshape)."""

    def to_units(Y: Array) -> Array:
        return np.array(Y, dtype=dtype, order="C", copy=True).reshape(Y.shape[0], -1)

    def from_units(A: Array) -> Array:
        return A.reshape(*A.shape[:-1], *core)

    return Layout(name, record, to_units, from_units, from_units, from_units)
