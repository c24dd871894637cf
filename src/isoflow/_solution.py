"""What a run returns and where it stands: :class:`Solution`, :class:`SolveStats`,
:class:`RunState` and the run status codes."""

from __future__ import annotations

import dataclasses
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ._failures import MemberFailures
from .diagnostics import Diagnostics

__all__ = ["RUN_FAILED", "RUN_FINISHED", "RUN_INTERRUPTED", "RunState", "Solution", "SolveStats"]

Array = NDArray[Any]

#: Status of a run (:attr:`Solution.status`): all requested steps taken.
RUN_FINISHED = 0
#: A step failed (for a single system; for an ensemble, at least one member).
RUN_FAILED = 1
#: Stopped by an exception from outside the numerics (Ctrl-C, a failed write).
RUN_INTERRUPTED = 2


@dataclass(frozen=True)
class SolveStats:
    """Counters of a run.

    Attributes
    ----------
    n_steps : int
        Steps completed (see :attr:`Solution.failed_step` for members that stopped earlier),
        counted from ``t0``: a resumed run's include those before its checkpoint.
    first_step : int
        The step this call started from: 0, or the checkpoint's step for a resumed run. The
        counters below (iterations, evaluations, times) are of the steps ``first_step + 1 ..
        n_steps``, the ones this call took.
    n_iterations : int
        Nonlinear iterations summed over steps and members (0 for explicit methods).
    n_B_evaluations : int
        Evaluations of ``B`` summed over members: one per fixed-point iteration, more for
        Newton's Jacobians, four per step for RK4 (validation calls not counted).
    iterations_mean, iterations_max : float, int
        Nonlinear iterations per step and member; the largest for one step.
    residual_max : float
        Largest final nonlinear residual of an accepted step.
    wall_time : float
        Seconds of the call: validation, compilation and the loop.
    compile_time : float
        Seconds of it that numba spent compiling or loading machine code from its cache (your
        function, the wrapper that calls it from Python, the compiled loops); about 0 when
        everything was compiled earlier in the process.
    runner : str
        What ran the steps: ``"NumPy"`` or ``"compiled, <layout>"``.
    threads : dict
        The threads the run used (:mod:`isoflow.threads`): ``"blas"``, the limit of every
        BLAS and OpenMP library during the loop; ``"numba"``, the numba threads the compiled
        loop ran its members (or chunks) on, 1 when it ran serially; ``"cores"``, the cores
        the process could run on.
    """

    n_steps: int = 0
    first_step: int = 0
    n_iterations: int = 0
    n_B_evaluations: int = 0
    iterations_mean: float = 0.0
    iterations_max: int = 0
    residual_max: float = 0.0
    wall_time: float = 0.0
    compile_time: float = 0.0
    runner: str = ""
    threads: dict[str, int] = dataclasses.field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        """Plain-Python dictionary (JSON-ready)."""
        return asdict(self)


@dataclass(frozen=True)
class Solution:
    """Result of :func:`isoflow.solve`.

    Attributes
    ----------
    ts : ndarray, shape (n_save,)
        Saved times ``t0 + k dt``.
    ys : ndarray, shape (n_save, *batch, *shape)
        Saved states, time first. A member that failed keeps its last good state.
    stats : SolveStats
    success : bool
        Whether every member took all requested steps.
    status : int
        :data:`RUN_FINISHED` (0), :data:`RUN_FAILED` (1, only with ``throw=False``) or
        :data:`RUN_INTERRUPTED` (2).
    message : str
        What happened, in words (naming the members that failed).
    diagnostics : Diagnostics or None
        Invariant drifts on the saved states (``None`` when ``diagnostics=False``).
    t0, dt : float
        Start time and step.
    n_steps : int
        Steps requested.
    failed_step : ndarray of int, shape batch
        Per member: the index of the step that failed (``0`` is the step from ``t0``; the
        member's last good state is at ``t0 + failed_step * dt``), ``-1`` for members that
        took every step.
    failure_reasons : dict
        Member index (a tuple, ``()`` for one system) -> why it failed.
    """

    ts: Array
    ys: Array
    stats: SolveStats
    success: bool
    status: int
    message: str
    diagnostics: Diagnostics | None
    t0: float
    dt: float
    n_steps: int
    failed_step: Array = dataclasses.field(default_factory=lambda: np.asarray(-1))
    failure_reasons: dict[tuple[int, ...], str] = dataclasses.field(default_factory=dict)

    @property
    def y_final(self) -> Array:
        """The last saved state (the final state when ``success``)."""
        return self.ys[-1]


@dataclass(frozen=True)
class RunState:
    """Where a run stands: what a checkpoint holds and a restart needs.

    Attributes
    ----------
    step : int
        Steps completed since ``t0``.
    y : ndarray
        The state after them, ``(*batch, *shape)``.
    method_state : object
        The method state after them (flattened ensemble members).
    failures : MemberFailures or None
        Members that failed earlier (frozen), ``None`` if none.
    """

    step: int
    y: Array
    method_state: Any = None
    failures: MemberFailures | None = None
