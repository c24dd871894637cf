r"""The Strang split step: a method for the isospectral part between two half steps of the
linear part and the forcing (:mod:`isoflow.splitting` has the equations).

.. math::

    \Phi_h = S_{h/2} \circ \Psi_h \circ S_{h/2}, \qquad
    S_\tau(W) = e^{\tau L} W + \sum_j a_j(t_{1/2}) \int_0^\tau e^{sL} F_j\,ds
        + \sum_j \sigma_j \sqrt{\tfrac{1 - e^{-2c_j\tau}}{2c_j}}\;\xi_j\, e_j ,

with :math:`t_{1/2}` the midpoint of the half step and :math:`\xi_j` standard normals (the
step data of the step, :meth:`Strang.step_data`: the same in the NumPy and the compiled path,
and in a resumed run). The method state is the base method's; the step data depend on the step
and the member alone.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from .._errors import ParameterError
from ..noise import standard_normals
from ..problems import IsospectralProblem
from ..splitting import (
    FORCING_STREAM,
    Deterministic,
    HalfStep,
    Stochastic,
    data_widths,
    half_step,
    split_terms,
)
from ._base import Method, StepDataRequest, StepResult
from .isomp import IsoMP

__all__ = ["Strang"]

Array = NDArray[Any]


@dataclass(frozen=True)
class Strang(Method):
    r"""Strang splitting of a problem's linear part and forcing with a method for its
    isospectral part (second order, symmetric when the base is).

    Parameters
    ----------
    base : Method
        The method for :math:`\dot W = [B(W), W]` (default :class:`~isoflow.IsoMP`). With
        IsoMP and the fixed-point solver the split step runs compiled wherever IsoMP does
        (dense spaces; on the others through the NumPy path).

    Notes
    -----
    A problem without linear part and forcing is stepped by the base method alone, bit for bit.
    A :class:`~isoflow.Composition` of the split step raises its order for deterministic,
    steady forcing; with time-dependent amplitudes or noise the step data belong to whole
    steps, so such a composition is refused.

    Examples
    --------
    >>> import isoflow as iso
    >>> prob, W0 = iso.models.euler_sphere(N=8, seed=1, viscosity=1e-3, drag=0.01)
    >>> sol = iso.solve(prob, iso.Strang(), W0, dt=0.1, n_steps=10)
    >>> sol.success, "Strang split" in sol.stats.runner
    (True, True)
    """

    base: Method = field(default_factory=IsoMP)
    _cache: dict[float, tuple[IsospectralProblem, HalfStep]] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )
    _terms_cache: list[tuple[IsospectralProblem, tuple[Deterministic, Stochastic]]] = field(
        default_factory=list, init=False, repr=False, compare=False
    )

    reads_step_data: ClassVar[bool] = True

    def __post_init__(self) -> None:
        if not isinstance(self.base, Method):
            raise ParameterError(
                f"Strang: base must be a Method such as iso.IsoMP(), got {self.base!r}"
            )
        if isinstance(self.base, Strang):
            raise ParameterError("Strang: the base is already a split method")

    # ---- the Method attributes that depend on the instance ----------------------------------
    @property  # type: ignore[misc]
    def order(self) -> int:  # type: ignore[override]
        return min(int(self.base.order), 2)

    @property  # type: ignore[misc]
    def implicit(self) -> bool:  # type: ignore[override]
        return bool(self.base.implicit)

    @property  # type: ignore[misc]
    def symmetric(self) -> bool:  # type: ignore[override]
        return bool(getattr(self.base, "symmetric", False))

    @property  # type: ignore[misc]
    def name(self) -> str:  # type: ignore[override]
        return f"Strang({self.base.name})"

    @property
    def integrates_noise(self) -> bool:  # type: ignore[override]
        """Whether the base integrates transport noise (its increments are the split step's
        last step data columns)."""
        return bool(self.base.integrates_noise)

    @property
    def solver(self) -> Any:
        """The base method's nonlinear solver (``None`` for an explicit base)."""
        return getattr(self.base, "solver", None)

    def for_problem(self, problem: IsospectralProblem) -> Strang:
        """The split step of the base's :meth:`~isoflow.Method.for_problem` (``self`` when
        the base settles nothing)."""
        base = self.base.for_problem(problem)
        return self if base is self.base else dataclasses.replace(self, base=base)

    # ---- stepping -----------------------------------------------------------------------------
    def init(self, problem: IsospectralProblem, y0: Array, h: float) -> Any:
        """The base method's initial state.

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
            What ``base.init`` returns.
        """
        return self.base.init(problem, y0, h)

    def half(self, problem: IsospectralProblem, tau: float) -> HalfStep:
        """The forcing terms of a half step ``tau`` (computed once per problem and step)."""
        hit = self._cache.get(tau)
        if hit is not None and hit[0] is problem:
            return hit[1]
        terms = half_step(problem, tau)
        self._cache[tau] = (problem, terms)
        return terms

    def _terms(self, problem: IsospectralProblem) -> tuple[Deterministic, Stochastic]:
        """:func:`~isoflow.splitting.split_terms` of ``problem``, kept for the last problem:
        checking the patterns against the space costs passes over ``N^2`` numbers, which
        every chunk of a run and every NumPy step would otherwise repeat."""
        cache = self._terms_cache
        hit = cache[0] if cache else None  # one read: another thread may replace the entry
        if hit is not None and hit[0] is problem:
            return hit[1]
        terms = split_terms(problem)
        cache[:] = [(problem, terms)]
        return terms

    def step_data(self, problem: IsospectralProblem, request: StepDataRequest) -> Array:
        """``(nsteps, members, 2 (R_d + R_s) + D)``: per half step the time-dependent
        amplitudes at its midpoint, then the standard normals of its noise modes (first half,
        second half; :func:`isoflow.splitting.data_widths`), then the ``D`` columns of the
        base's own step data when it reads some (the transport noise's increments of
        :class:`~isoflow.StochasticIsoMP`, drawn as the base alone draws them).

        Parameters
        ----------
        problem : IsospectralProblem
            The problem to advance.
        request : StepDataRequest
            The steps, the members and the step size the data are for. Step ``k`` starts at
            ``request.t0 + (k - 1) h``; the amplitudes are taken at the midpoints of its two
            half steps.

        Returns
        -------
        ndarray, shape (nsteps, members, 2 (R_d + R_s) + D)
        """
        det, sto = self._terms(problem)
        rd, rs = data_widths(problem, (det, sto))
        members = np.asarray(request.members, dtype=np.int64).reshape(-1)
        n, h = int(request.nsteps), float(request.h)
        out = np.zeros((n, members.size, 2 * (rd + rs)))
        if rd:
            for s in range(n):
                t = request.t0 + (request.k0 + s) * h
                for half, tm in enumerate((t + 0.25 * h, t + 0.75 * h)):
                    a = np.concatenate(
                        [f.amplitudes(tm, len(P)) for f, P in det if f.time_dependent]
                    )
                    out[s, :, half * (rd + rs) : half * (rd + rs) + rd] = a
        if rs:
            col = 0
            for f, modes, _ in sto:
                r = modes.size
                xi = standard_normals(
                    int(f.seed), members, request.k0, n, 2 * r, stream=FORCING_STREAM
                )
                out[:, :, rd + col : rd + col + r] = xi[:, :, :r]
                out[:, :, 2 * rd + rs + col : 2 * rd + rs + col + r] = xi[:, :, r:]
                col += r
        if self.base.reads_step_data:
            base = np.asarray(self.base.step_data(problem, request), dtype=np.float64)
            out = np.concatenate([out, base.reshape(n, members.size, -1)], axis=-1)
        return out

    def _half_step(
        self, problem: IsospectralProblem, W: Array, tau: float, data: Array | None
    ) -> Array:
        """:math:`S_\\tau(W)` with the half step's step data ``data`` (``(*batch, R_d + R_s)``)."""
        lin = problem.linear_part
        if lin is not None:
            W = lin.flow(W, tau)
        terms = self.half(problem, tau)
        if terms.steady is not None:
            W = W + terms.steady
        rd = 0 if terms.responses is None else len(terms.responses)
        if terms.responses is not None:
            assert data is not None
            W = W + np.tensordot(data[..., :rd], terms.responses, axes=(-1, 0))
        if terms.noise is not None:  # sparse (R_s, S): the normals times their modes
            assert data is not None
            xi = np.asarray(data[..., rd:], dtype=np.float64)
            add = (terms.noise.T @ xi.reshape(-1, xi.shape[-1]).T).T
            W = W + add.reshape(W.shape)
        return W

    def step(
        self,
        problem: IsospectralProblem,
        y: Array,
        h: float,
        state: Any = None,
        data: Array | None = None,
    ) -> StepResult:
        """One Strang step: half a step of the linear part and forcing, the base's step, and
        the second half.

        Parameters
        ----------
        problem : IsospectralProblem
            The problem to advance.
        y : ndarray, shape (*batch, *shape)
            The state at the start of the step.
        h : float
            The step size (each half step has ``h / 2``).
        state : object, optional
            The base method's state, passed on to its step.
        data : ndarray, shape (*batch, 2 (R_d + R_s) + D), optional
            The step's data (:meth:`step_data`); required when the forcing has
            time-dependent amplitudes or noise, or the base reads step data.

        Returns
        -------
        StepResult
            The new state with the base step's stage, solve record and state.

        Raises
        ------
        ParameterError
            Step data needed but not given (a split step inside a composition).
        """
        rd, rs = data_widths(problem, self._terms(problem))
        half = rd + rs
        own: dict[str, Array] = {}
        if self.base.reads_step_data:
            if data is None:
                raise ParameterError(
                    f"{self.name}: the base reads step data (noise increments) of whole "
                    "steps: step it through iso.solve or iso.step, not inside a composition"
                )
            own = {"data": data[..., 2 * half :]}
        if problem.linear_part is None and not problem.forcing:
            return self.base.step(problem, y, h, state, **own)
        if half and data is None:
            raise ParameterError(
                f"{self.name}: the forcing has time-dependent amplitudes or noise, which are "
                "read per whole step (step data): step it through iso.solve, not inside a "
                "composition"
            )
        first = None if data is None else data[..., :half]
        second = None if data is None else data[..., half : 2 * half]
        tau = 0.5 * h
        y1 = self._half_step(problem, y, tau, first)
        res = self.base.step(problem, y1, h, state, **own)
        y2 = self._half_step(problem, res.y, tau, second)
        return StepResult(
            y=y2,
            stage=res.stage,
            iterations=res.iterations,
            residual=res.residual,
            status=res.status,
            state=res.state,
        )
