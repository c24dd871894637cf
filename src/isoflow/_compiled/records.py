"""Typed records that carry a run's constants into the compiled driver.

Named tuples (numba types them field by field), so the driver takes a handful of typed records
instead of a long positional list, and its signature is derived from the records themselves
(:mod:`isoflow._compiled.signatures`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from .._save_grid import SaveGrid
from ..nonlinear import ANDERSON_REGULARIZATION, FixedPoint

__all__ = ["Plan", "SolverConstants", "no_step_data"]


class SolverConstants(NamedTuple):
    """The fixed-point solver's constants (:class:`isoflow.FixedPoint`), as the driver reads
    them; see :mod:`isoflow.nonlinear` for the rules they parametrize."""

    rtol: float
    atol: float
    stall_rtol: float
    divergence_factor: float
    max_iter: int
    anderson: int
    regularization: float

    @classmethod
    def of(cls, solver: FixedPoint) -> SolverConstants:
        """The constants of ``solver``."""
        return cls(
            float(solver.rtol), float(solver.atol), float(solver.stall_rtol),
            float(solver.divergence_factor), int(solver.max_iter), int(solver.anderson),
            ANDERSON_REGULARIZATION,
        )  # fmt: skip


class Plan(NamedTuple):
    """What one call of the driver does.

    Attributes
    ----------
    h : float
        The step.
    nsteps : int
        Steps to take.
    k0 : int
        Steps taken before the call (the first step of the call is step ``k0 + 1``).
    save_every, k_final : int
        The save grid (:class:`isoflow._save_grid.SaveGrid`): the state after step ``k``
        is saved when ``k % save_every == 0`` or ``k == k_final``.
    kmax : int
        Stage offsets kept for the initial guess (0: start from the state).
    begin : bool
        Whether the stage has an explicit part before its solve (a split step's half flow,
        the stochastic step's noise term).
    begin_moves : bool
        Whether that part changes the state (a split step's half flow) and not only scratch
        rows: the driver then keeps the state a step starts from, to freeze a failed lane
        there.
    kint : int
        Offsets of the interpolating start a fitted start falls back to when it would have
        predicted the newest offset within half the tolerance (its weights are the last row
        of ``coefs``; :func:`isoflow._compiled.flat.guess_or_fit`); 0: the start is never
        switched.
    """

    h: float
    nsteps: int
    k0: int
    save_every: int
    k_final: int
    kmax: int
    begin: bool
    begin_moves: bool
    kint: int = 0

    @classmethod
    def of(
        cls, h: float, nsteps: int, k0: int, grid: SaveGrid, kmax: int, begin: bool,
        begin_moves: bool = True, kint: int = 0,
    ) -> Plan:  # fmt: skip
        """The plan of a call of ``nsteps`` steps from ``k0`` on ``grid``."""
        return cls(
            float(h), int(nsteps), int(k0), int(grid.every), int(grid.k_final), int(kmax),
            bool(begin), bool(begin and begin_moves), int(kint),
        )  # fmt: skip


def no_step_data(nsteps: int, members: int) -> NDArray[np.float64]:
    """Step data of a stage that reads none: ``(nsteps, members, 0)``, no memory."""
    return np.empty((max(nsteps, 1), members, 0))
