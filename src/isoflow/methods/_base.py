"""The contract every time-stepping method fulfils (see :class:`Method`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from ..nonlinear import STATUS_CONVERGED, STATUS_NAMES
from ..problems import IsospectralProblem

__all__ = ["AdvanceResult", "Method", "StepResult"]

Array = NDArray[Any]


@dataclass(frozen=True)
class StepResult:
    """One step ``y -> y_next`` of a method.

    Attributes
    ----------
    y : ndarray
        The new state, shape ``(*batch, *shape)``.
    stage : ndarray or None
        The implicit stage (``X`` for IsoMP, the midpoint for midpoint rules); ``None`` for
        explicit methods.
    iterations, residual, status : ndarray or None
        Per-member nonlinear-solve record (``None`` for explicit methods).
    state : object
        Whatever the method carries to the next step (e.g. the warm start).
    """

    y: Array
    stage: Array | None = None
    iterations: NDArray[np.int64] | None = None
    residual: NDArray[np.float64] | None = None
    status: NDArray[np.int64] | None = None
    state: Any = None

    @property
    def success(self) -> bool:
        """Whether every member's nonlinear solve converged (always true for explicit methods)."""
        return self.status is None or bool(np.all(self.status == STATUS_CONVERGED))

    def failure_reason(self) -> str:
        """Name of the first failure code, ``"converged"`` if none."""
        if self.status is None or self.success:
            return "converged"
        code = int(self.status[self.status != STATUS_CONVERGED].flat[0])
        return STATUS_NAMES.get(code, str(code))


@dataclass(frozen=True)
class AdvanceResult:
    """``n`` steps of a method taken in one call (see :meth:`Method.advance`).

    Attributes
    ----------
    y : ndarray
        State after the ``n_done`` accepted steps.
    state : object
        Method state after them.
    n_done : int
        Steps accepted; fewer than requested only if ``failure`` is set.
    iterations_total, iterations_max : int
        Nonlinear iterations summed over steps and members, and the largest per step/member.
    residual_max : float
        Largest final residual of the accepted steps.
    failure : StepResult or None
        The rejected step (non-converged solve or non-finite result), if any.
    """

    y: Array
    state: Any
    n_done: int
    iterations_total: int = 0
    iterations_max: int = 0
    residual_max: float = 0.0
    failure: StepResult | None = None


class Method:
    r"""Base of the integrators: a small frozen dataclass with ``init`` and ``step``.

    A method advances ``problem`` by one fixed step ``h`` with :meth:`step`; the solve loop owns
    everything else (saving, diagnostics, failure policy). ``state`` is opaque to the loop, but
    must be ``None`` or a tuple of floats and NumPy arrays, so that a run can be checkpointed and
    resumed bit for bit (e.g. IsoMP's warm start ``(h, X_k - W_k)``).

    Attributes
    ----------
    order : int
        Classical order of accuracy.
    implicit : bool
        Whether a nonlinear solve is involved (and may fail).
    symmetric : bool
        Whether the step map is symmetric (self-adjoint), :math:`\Phi_{-h} \circ \Phi_h =
        \mathrm{id}`; only symmetric methods can be raised in order by symmetric composition
        (:class:`~isoflow.Composition`).
    name : str
        Human-readable name (also recorded in result files and checked on resume).

    Notes
    -----
    Every array in ``state`` that belongs to ensemble members has the batch axes leading,
    shape ``(*batch, ...)``, so that members can be selected by indexing those axes.
    """

    order: ClassVar[int]
    implicit: ClassVar[bool]
    symmetric: ClassVar[bool] = False
    name: ClassVar[str]

    def init(self, problem: IsospectralProblem, y0: Array, h: float) -> Any:
        """Initial method state (default: none)."""
        return None

    def step(
        self, problem: IsospectralProblem, y: Array, h: float, state: Any = None
    ) -> StepResult:  # pragma: no cover - abstract
        raise NotImplementedError

    def advance(
        self, problem: IsospectralProblem, y: Array, h: float, n: int, state: Any = None
    ) -> AdvanceResult:
        """Take ``n`` steps of size ``h``; stop at the first step that fails.

        The solve loop calls this between two saved states. The default loops over
        :meth:`step`; compiled fast paths override it to run the whole loop in machine code.
        A failed step is not accepted: ``y`` is then the last good state.
        """
        total = largest = 0
        res_max = 0.0
        for i in range(n):
            res = self.step(problem, y, h, state)
            if res.iterations is not None:
                total += int(np.sum(res.iterations))
                largest = max(largest, int(np.max(res.iterations)))
            if not res.success or not np.all(np.isfinite(res.y)):
                return AdvanceResult(y, state, i, total, largest, res_max, failure=res)
            if res.residual is not None:
                res_max = max(res_max, float(np.max(res.residual)))
            y, state = res.y, res.state
        return AdvanceResult(y, state, n, total, largest, res_max)
