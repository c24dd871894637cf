"""The contract every time-stepping method fulfils (see :class:`Method`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from .._errors import ParameterError
from .._failures import NAMES
from ..nonlinear import STATUS_CONVERGED, NonlinearResult, NonlinearSolver
from ..problems import IsospectralProblem

__all__ = ["Method", "StepDataRequest", "StepResult", "check_implicit_options"]

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

    @classmethod
    def from_solve(cls, y: Array, res: NonlinearResult, state: Any = None) -> StepResult:
        """The step to ``y`` whose implicit stage and solve record are those of ``res``.

        Parameters
        ----------
        y : ndarray, shape (*batch, *shape)
            The new state.
        res : NonlinearResult
            The solve of the step's stage: its solution ``x`` becomes :attr:`stage`, its
            ``iterations``, ``residual`` and ``status`` the solve record.
        state : object, optional
            The method state for the next step (default ``None``).
        """
        return cls(
            y=y,
            stage=res.x,
            iterations=res.iterations,
            residual=res.residual,
            status=res.status,
            state=state,
        )

    @property
    def success(self) -> bool:
        """Whether every member's nonlinear solve converged (always true for explicit methods)."""
        return self.status is None or bool(np.all(self.status == STATUS_CONVERGED))

    def failure_reason(self) -> str:
        """Name of the first failure code, ``"converged"`` if none."""
        if self.status is None or self.success:
            return "converged"
        code = int(self.status[self.status != STATUS_CONVERGED].flat[0])
        return NAMES.get(code, str(code))


@dataclass(frozen=True)
class StepDataRequest:
    """What a method's step data is for: the steps ``k0 + 1 .. k0 + nsteps`` of the members
    ``members`` (their indices in the run, flattened; ``-1`` for the padding lanes of a compiled
    unit), with step ``h``. Step ``k`` goes from ``t0 + (k - 1) h`` to ``t0 + k h``."""

    k0: int
    nsteps: int
    members: Any
    h: float
    t0: float = 0.0


class Method:
    r"""Base of the integrators: a small frozen dataclass with ``init`` and ``step``.

    A method advances ``problem`` by one fixed step ``h`` with :meth:`step`; the time loop owns
    everything else (saving, diagnostics, failure policy, the ensemble members that failed).
    ``state`` is opaque to the loop, but must be ``None`` or a flat tuple of floats, integers
    and NumPy arrays, so that a run can be checkpointed and resumed bit for bit (e.g. IsoMP's
    warm start ``(h, X_k - W_k, ...)``); an array with one entry per ensemble member has the
    members on its leading axes, like the state, so that the loop can step a subset of them.

    Methods never import the compiled layer (:mod:`isoflow._compiled`): the time loop asks it
    for a compiled runner of the (method, problem) pair and otherwise calls :meth:`step`.

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
    A method that reads step data (:attr:`reads_step_data`) takes it as the keyword ``data``
    of :meth:`step`: the rows ``(*batch, D)`` of the step's members.

    Every array in ``state`` that belongs to ensemble members has the batch axes leading,
    shape ``(*batch, ...)``, so that members can be selected by indexing those axes.
    """

    order: ClassVar[int]
    implicit: ClassVar[bool]
    symmetric: ClassVar[bool] = False
    name: ClassVar[str]
    #: Whether the steps read *step data* (noise increments, a forcing's amplitudes at the
    #: step's times): a function of the method, the problem, the step and the member alone
    #: (:meth:`step_data`), handed to :meth:`step` as ``data`` by the time loop, so that a
    #: resumed or split run reads the same.
    reads_step_data: ClassVar[bool] = False
    #: Whether the steps integrate a problem's transport noise
    #: (:class:`~isoflow.noise.TransportNoise`) from their step data; the others refuse a
    #: problem with noise.
    integrates_noise: ClassVar[bool] = False

    def step_data(self, problem: IsospectralProblem, request: StepDataRequest) -> Array:
        """The step data ``(nsteps, members, D)`` of ``request`` (methods that read some).

        A function of the method, the problem, the step numbers and the members only, so that
        a resumed or split run reads the same data.

        Parameters
        ----------
        problem : IsospectralProblem
            The problem to advance.
        request : StepDataRequest
            The steps, the members and the step size the data are for.

        Returns
        -------
        ndarray, shape (nsteps, members, D)
            Row ``s`` is the data of step ``request.k0 + s + 1``.
        """
        raise NotImplementedError  # pragma: no cover

    def for_problem(self, problem: IsospectralProblem) -> Method:
        """This method with the defaults that depend on the problem settled (default: itself).

        The time loop calls it once when a run starts or resumes, and records the result's
        settings in the run's file; e.g. :meth:`isoflow.StochasticIsoMP.for_problem` loosens
        its default stage tolerance where the step keeps every Casimir whatever the tolerance.

        Parameters
        ----------
        problem : IsospectralProblem
            The problem the run integrates.

        Returns
        -------
        Method
            A method of the same class (``self`` when nothing depends on the problem).
        """
        return self

    def init(self, problem: IsospectralProblem, y0: Array, h: float) -> Any:
        """Initial method state (default: none).

        Parameters
        ----------
        problem : IsospectralProblem
            The problem to advance.
        y0 : ndarray, shape (*batch, *shape)
            The initial state, in the problem's space.
        h : float
            The step size.

        Returns
        -------
        object
            ``None`` or a flat tuple of floats, integers and arrays (class docstring), handed
            to the first :meth:`step`.
        """
        return None

    def step(
        self, problem: IsospectralProblem, y: Array, h: float, state: Any = None
    ) -> StepResult:  # pragma: no cover - abstract
        """One step of size ``h`` from ``y``.

        Parameters
        ----------
        problem : IsospectralProblem
            The problem to advance.
        y : ndarray, shape (*batch, *shape)
            The state at the start of the step.
        h : float
            The step size.
        state : object, optional
            The method state returned by :meth:`init` or by the previous step (``None``: no
            history, e.g. a step taken on its own).

        Returns
        -------
        StepResult
            The new state, the implicit stage and solve record (implicit methods) and the
            method state for the next step.
        """
        raise NotImplementedError


#: The highest degree of the extrapolated initial guess (:class:`~isoflow.IsoMP`).
MAX_EXTRAPOLATION_ORDER = 7


def check_implicit_options(
    solver: object, initial_guess: object, extrapolation_order: object = 0,
    *, default_order: bool = False,
) -> None:  # fmt: skip
    """Check the options the implicit methods share (``default_order``: ``None`` is a valid
    ``extrapolation_order``, the space's default).

    Raises
    ------
    ParameterError
        ``solver`` is not a :class:`~isoflow.nonlinear.NonlinearSolver` instance,
        ``initial_guess`` is not ``"extrapolate"`` or ``"state"``, or
        ``extrapolation_order`` is not an integer in ``[0, MAX_EXTRAPOLATION_ORDER]``.
    """
    if not isinstance(solver, NonlinearSolver):
        raise ParameterError(f"solver must be FixedPoint() or Newton(), got {solver!r}")
    if initial_guess not in ("extrapolate", "state"):
        raise ParameterError(
            f"initial_guess must be 'extrapolate' or 'state', got {initial_guess!r}"
        )
    p = extrapolation_order
    top = MAX_EXTRAPOLATION_ORDER
    if p is None and default_order:
        return
    if isinstance(p, bool) or not isinstance(p, (int, np.integer)) or not 0 <= p <= top:
        raise ParameterError(f"extrapolation_order must be an integer in [0, {top}], got {p!r}")
