r"""One vocabulary of failures: the codes, their names, the messages and the exceptions.

A step of a member fails for one of these reasons (the code is what the nonlinear solvers
return, what the compiled driver records per member and what a result file stores):

==========  ===============  ========================================  =========================
code        name             when                                      exception (``throw``)
==========  ===============  ========================================  =========================
0           converged        (not a failure)                           --
1           max_iter         the solve used ``max_iter`` iterations    :class:`ConvergenceError`
2           diverged         the residual grew beyond the factor       :class:`ConvergenceError`
3           non_finite       a residual or the new state is NaN/Inf    :class:`NonFiniteError`
                                                                       (the state), else
                                                                       :class:`ConvergenceError`
4           B raised         the user's ``B`` raised                   :class:`IsoflowError`,
                                                                       the exception as cause
5           left the space   ``B`` at a saved state left the           :class:`NotInSpaceError`
                             normalizer
==========  ===============  ========================================  =========================

A member that fails is frozen at its last good state and the others go on
(:class:`MemberFailures` records who, when and why); with ``throw=True`` the run then raises
the exception of the first failure (:func:`exception_for`), after writing what it computed.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ._errors import ConvergenceError, IsoflowError, NonFiniteError, NotInSpaceError

__all__ = [
    "B_RAISED",
    "CONVERGED",
    "DIVERGED",
    "LEFT_SPACE",
    "MAX_ITER",
    "NAMES",
    "NON_FINITE",
    "MemberFailures",
    "describe",
    "exception_for",
    "step_exception",
]

CONVERGED = 0
MAX_ITER = 1
DIVERGED = 2
NON_FINITE = 3
B_RAISED = 4
LEFT_SPACE = 5

#: The name of every code, as messages and result files spell it.
NAMES = {
    CONVERGED: "converged",
    MAX_ITER: "max_iter",
    DIVERGED: "diverged",
    NON_FINITE: "non_finite",
    B_RAISED: "B raised",
    LEFT_SPACE: "left the space",
}

#: What a user can do about a failed solve.
_ADVICE = "Reduce dt (h * ||B(W)|| should stay well below 2) or change the solver."


@dataclass
class MemberFailures:
    """Which ensemble members failed, when and why (flattened member index).

    Attributes
    ----------
    step : ndarray of int, shape (M,)
        Index of the step that failed (``0``: the step from ``t0``; the member's last good
        state is after ``step`` steps); ``-1`` while alive.
    status : ndarray of int
        Failure code (:data:`NAMES`); 0 while alive.
    iterations : ndarray of int
        Iterations spent on the failed step.
    residual : ndarray of float
        Final residual of the failed solve.
    messages : dict of int to str
        A message per member where there is more to say (the exception ``B`` raised).
    """

    step: NDArray[np.int64]
    status: NDArray[np.int64]
    iterations: NDArray[np.int64]
    residual: NDArray[np.float64]
    messages: dict[int, str] = field(default_factory=dict)

    @classmethod
    def none(cls, members: int) -> MemberFailures:
        """A record of ``members`` members, all alive."""
        return cls(
            step=np.full(members, -1, dtype=np.int64),
            status=np.zeros(members, dtype=np.int64),
            iterations=np.zeros(members, dtype=np.int64),
            residual=np.zeros(members),
        )

    @property
    def alive(self) -> NDArray[np.bool_]:
        """Per member: not failed."""
        return self.step < 0

    @property
    def failed(self) -> NDArray[np.int64]:
        """Flat indices of the failed members."""
        return np.flatnonzero(self.step >= 0)

    def record(self, m: int, step: int, status: int, iterations: int, residual: float) -> None:
        """Mark member ``m`` failed at ``step``."""
        self.step[m] = step
        self.status[m] = status
        self.iterations[m] = iterations
        self.residual[m] = residual

    def reason(self, m: int) -> str:
        """The failure of member ``m`` in words."""
        name = NAMES.get(int(self.status[m]), str(int(self.status[m])))
        extra = self.messages.get(int(m))
        return f"{name}: {extra}" if extra else name

    def first(self) -> int:
        """The member that failed first (the lowest step; the lowest index among equals)."""
        idx = self.failed
        return int(idx[np.argmin(self.step[idx])])

    def state_non_finite(self, m: int) -> bool:
        """Whether member ``m`` failed because its new state was not finite (a converged or
        explicit step), rather than in its solve."""
        return int(self.status[m]) == NON_FINITE and int(self.iterations[m]) <= 1


def describe(
    method: str, failures: MemberFailures, batch: tuple[int, ...], t0: float, dt: float
) -> str:
    """The run's failure in words: the one system's, or a list of the failed members."""
    if batch == ():
        m = 0
        k = int(failures.step[m])
        t = t0 + k * dt
        code = int(failures.status[m])
        if code == B_RAISED:
            return f"{method}: at step {k} (t = {t:.6g}) {failures.reason(m)}"
        if code == LEFT_SPACE:
            return (
                f"{method}: {failures.reason(m)}; the run stops at the last saved state "
                f"where B was in the normalizer, after step {k} (t = {t:.6g})"
            )
        if failures.state_non_finite(m):
            return f"{method}: the state became non-finite at step {k} (t = {t:.6g})"
        return (
            f"{method}: the nonlinear solve of step {k} (t = {t:.6g}) did not converge "
            f"({failures.reason(m)}): residual {failures.residual[m]:.3e} after "
            f"{int(failures.iterations[m])} iterations. {_ADVICE}"
        )
    idx = failures.failed
    shown = ", ".join(
        f"{tuple(int(i) for i in np.unravel_index(int(m), batch))} at step "
        f"{int(failures.step[m])} ({failures.reason(int(m))})"
        for m in idx[:5]
    )
    more = f" and {idx.size - 5} more" if idx.size > 5 else ""
    total = int(np.prod(batch))
    rest = "The other members took every step." if idx.size < total else "No member is left."
    solves = [  # the advice is for a solve that failed, as for one system
        int(failures.status[m]) not in (B_RAISED, LEFT_SPACE)
        and not failures.state_non_finite(int(m))
        for m in idx
    ]
    advice = f" {_ADVICE}" if any(solves) else ""
    return (
        f"{method}: {idx.size} of {total} ensemble member(s) failed and were frozen at their "
        f"last good state: {shown}{more}. {rest}{advice}"
    )


def exception_for(
    message: str, failures: MemberFailures, causes: dict[int, BaseException], t0: float,
    dt: float,
) -> Exception:  # fmt: skip
    """The exception a run with ``throw=True`` raises for its first failed member
    (``causes``: per member, the exception behind its failure)."""
    m = failures.first()
    k = int(failures.step[m])
    code = int(failures.status[m])
    cause = causes.get(m)
    if code == LEFT_SPACE and isinstance(cause, NotInSpaceError):
        return NotInSpaceError(message, distance=cause.distance, tolerance=cause.tolerance)
    if code == B_RAISED:
        exc: Exception = IsoflowError(message)
        exc.__cause__ = cause
        return exc
    # a state that turned non-finite under an explicit method (no residual) too: one type for
    # one system and for an ensemble, with the reason "non_finite"
    return ConvergenceError(
        message,
        step=k,
        time=t0 + k * dt,
        residual=float(failures.residual[m]),
        iterations=int(failures.iterations[m]),
        reason=failures.reason(m).split(":")[0],
    )


def step_exception(method: str, res: Any, k: int, t: float) -> Exception:
    """The exception of a rejected single step ``k`` from time ``t`` (:func:`isoflow.step`):
    ``res`` is its :class:`~isoflow.methods.StepResult`."""
    if not res.success:
        status = np.asarray(res.status)
        bad = int(np.count_nonzero(status != CONVERGED))
        reason = res.failure_reason()
        residual = float(np.max(res.residual))
        iterations = int(np.max(res.iterations))
        return ConvergenceError(
            f"{method}: the nonlinear solve of step {k} (t = {t:.6g}) did not converge "
            f"({reason}) for {bad} of {status.size} ensemble member(s): residual "
            f"{residual:.3e} after {iterations} iterations. {_ADVICE}",
            step=k, time=t, residual=residual, iterations=iterations, reason=reason,
        )  # fmt: skip
    return NonFiniteError(f"{method}: the state became non-finite at step {k} (t = {t:.6g})")
