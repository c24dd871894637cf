r"""The stochastic isospectral midpoint for Stratonovich transport noise.

For the stochastic Lie–Poisson system (:class:`isoflow.noise.TransportNoise`)

.. math::

    dW = [B(W), W]\,dt + \sum_{i=1}^m [B_i(W), W] \circ d\beta_i(t),

one step ``W_k -> W_{k+1}`` over ``[t_k, t_k + h]`` with the increments
:math:`\Delta\beta_i = \beta_i(t_k + h) - \beta_i(t_k)` is IsoMP with :math:`h B(X)` replaced by

.. math::

    \tilde B(X) = h B(X) + \sum_i \Delta\beta_i B_i(X), \qquad
    W_k = (I - \tfrac12 \tilde B)\, X\, (I + \tfrac12 \tilde B), \qquad
    W_{k+1} = (I + \tfrac12 \tilde B)\, X\, (I - \tfrac12 \tilde B)

(Ephrati, Jansson, Lang, Luesink, arXiv:2408.16701): the fixed point of
:math:`G(X) = W_k + \tfrac12 [\tilde B, X] + \tfrac14 \tilde B X \tilde B` and
:math:`W_{k+1} = W_k + [\tilde B, X]`, a Cayley conjugation of :math:`W_k`, so every Casimir is
kept for every path (almost surely). The paper proves root-mean-square (strong) order 1/2 and
weak order 1; with commuting noise fields the strong order is 1. The increments are the
reproducible ones of :mod:`isoflow.noise` (truncated, by default, as the paper's analysis
assumes: see :func:`isoflow.noise.truncation_level`). The derivation is in
``docs/theory/stochastic.rst``.

Written as IsoMP on the field :math:`B(X) + \tfrac1h \sum_i \Delta\beta_i B_i(X)`, so the compiled
stage is IsoMP's with one more term (:mod:`isoflow._compiled.stages.stochastic_isomp`).

**The Cayley update** (``update="cayley"``). The step above is isospectral only to the stage's
residual: the solver's tolerance (``1e-14``) is what keeps the Casimirs at rounding, and each
iteration gains about one digit, from the state (the stage offsets of a noisy path are not
smooth in time, so there is no extrapolated start). As :class:`~isoflow.IsoMP`'s option of the
same name, the step can end instead with the Cayley factor of the accepted stage's field,

.. math::

    W_{k+1} = C W_k C^\dagger, \qquad
    C = \big(I - \tfrac12 \tilde B\big)^{-1} \big(I + \tfrac12 \tilde B\big),

unitary for every skew :math:`\tilde B`, so every Casimir is kept to rounding whatever the
stage's error. When the stage is solved exactly the two updates coincide (from the step's two
equations, :math:`W_{k+1} = (I + \tfrac12\tilde B)(I - \tfrac12\tilde B)^{-1} W_k
(I + \tfrac12\tilde B)^{-1} (I - \tfrac12\tilde B)`). A loose tolerance then only moves the step
by the stage's error, far below the method's own (strong order 1/2): the default tolerance is
``1e-8`` (:data:`~isoflow.methods.isomp.CAYLEY_RTOL`), about half the iterations. The finish costs
one inverse and two products (:func:`~isoflow.methods.isomp.cayley_increment`).

**Spins and vortices.** On :math:`(\mathbb{R}^3,\times)^N` each particle's stage is solved in
closed form for the field of the iterate and both updates rotate every :math:`w_i` by the same
Cayley factor (:class:`isoflow.algebras.SpinVectors`), so the lengths are kept whatever the
tolerance: there the default tolerance with noise is ``1e-8`` for either update
(:meth:`StochasticIsoMP.for_problem`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

import numpy as np
from numpy.typing import NDArray

from .._errors import ParameterError
from ..algebras import Algebra
from ..noise import TRANSPORT_STREAM, TransportNoise, brownian_increments, check_truncation
from ..nonlinear import FixedPoint, NonlinearSolver
from ..problems import IsospectralProblem
from ..splitting import has_split_part
from ._base import Method, StepDataRequest, StepResult, check_implicit_options
from .isomp import (
    CAYLEY_RTOL,
    IsoMP,
    cayley_increment,
    check_update_space,
    update_solver,
)

__all__ = ["StochasticIsoMP"]

Array = NDArray[Any]


@dataclass(frozen=True)
class StochasticIsoMP(Method):
    r"""The stochastic isospectral midpoint (strong order 1/2, weak order 1).

    Parameters
    ----------
    solver : FixedPoint or Newton, optional
        Nonlinear solver for the stage (as :class:`~isoflow.IsoMP`). Each solve starts from the
        state: the stage offsets of a noisy path are not smooth in time, so IsoMP's
        extrapolated guess does not apply. Default: ``FixedPoint()`` (tolerance ``1e-14``),
        and ``FixedPoint(rtol=1e-8)`` (:data:`~isoflow.methods.isomp.CAYLEY_RTOL`) wherever
        the step keeps every Casimir whatever the tolerance: with ``update="cayley"``, and on
        :math:`(\mathbb{R}^3,\times)^N` with noise (thermal spins, stochastic point vortices),
        where each particle's stage is solved in closed form for the field of the iterate and
        the step rotates every :math:`w_i` (:meth:`for_problem`, the module docstring).
    truncation : float or None
        ``k`` of the truncated increments :math:`\sqrt h\,\zeta`, :math:`|\zeta| \le A_h =
        \sqrt{2k|\ln h|}` (default 2: strong order 1/2 and weak order 1 kept); ``None`` draws
        Gaussian increments (a step whose solve then diverges fails its member).
    substeps : int
        A step's increments are the sums of those of ``substeps`` steps of size ``h /
        substeps`` (truncated at that size): a run with step ``h`` then lies on the Brownian
        path of the run with step ``h / substeps`` and the same seed, which is what a
        strong-convergence study compares (default 1: the step's own increments).
    update : {"midpoint", "cayley"}
        How the step ends: ``"midpoint"`` (default), :math:`W_{k+1} = W_k + [\tilde B, X]`;
        ``"cayley"``, :math:`W_{k+1} = C W_k C^\dagger` with the Cayley factor of
        :math:`\tilde B` (the module docstring), isospectral to rounding whatever the
        solver's tolerance, whose default is then ``1e-8``. Dense matrix spaces (``so``,
        ``u``, ``su``, ``sym``, ``herm``) and :math:`(\mathbb{R}^3,\times)^N` (thermal
        spins: every ``|S_i|`` kept by a rotation); the method's :attr:`name` is then
        ``"stochastic IsoMP (Cayley update)"``, so a run resumes with the update it began
        with.

    Notes
    -----
    The problem's :class:`~isoflow.noise.TransportNoise` gives the fields and the seed; a
    problem without noise is integrated as IsoMP from the state, bit for bit. Step ``k`` of
    member ``j`` uses the increments keyed by ``(seed, noise.member_ids(M)[j], k)``.

    Examples
    --------
    >>> import isoflow as iso
    >>> prob, W0 = iso.models.rigid_body(3, noise=0.2, noise_seed=1)
    >>> sol = iso.solve(prob, iso.StochasticIsoMP(), W0, dt=0.01, n_steps=100)
    >>> bool(sol.diagnostics.casimir_drift < 1e-13)
    True
    """

    # ``None`` is resolved by ``__post_init__`` (it depends on ``update``): always a solver after
    solver: NonlinearSolver = None  # type: ignore[assignment]
    truncation: float | None = 2.0
    substeps: int = 1
    update: Literal["midpoint", "cayley"] = "midpoint"
    #: Whether ``solver`` was left to its default (which :meth:`for_problem` may loosen).
    _default_solver: bool = field(default=False, init=False, repr=False)

    order: ClassVar[int] = 1
    implicit: ClassVar[bool] = True
    symmetric: ClassVar[bool] = False
    reads_step_data: ClassVar[bool] = True
    integrates_noise: ClassVar[bool] = True

    def __post_init__(self) -> None:
        object.__setattr__(self, "_default_solver", self.solver is None)
        solver = update_solver("StochasticIsoMP", self.update, self.solver)
        object.__setattr__(self, "solver", solver)
        check_implicit_options(self.solver, "state")
        object.__setattr__(self, "truncation", check_truncation(self.truncation))
        check_substeps(self.substeps)

    @property
    def name(self) -> str:  # type: ignore[override]
        """``"stochastic IsoMP"``, or ``"stochastic IsoMP (Cayley update)"`` with
        ``update="cayley"``."""
        return "stochastic IsoMP" + ("" if self.update == "midpoint" else " (Cayley update)")

    def for_problem(self, problem: IsospectralProblem) -> StochasticIsoMP:
        r"""With the default solver, on :math:`(\mathbb{R}^3,\times)^N` with noise: the same
        method with ``FixedPoint(rtol=CAYLEY_RTOL)`` (``1e-8``); else ``self``.

        There each particle's stage is solved in closed form for the field of the iterate
        (:attr:`isoflow.algebras.Algebra.closed_form_stage`) and the step rotates every
        :math:`w_i` by the Cayley factor of that field, so every :math:`|w_i|` is kept to
        rounding whatever the stage's error, as with the Cayley update; the stage's error then
        only moves the step, orders of magnitude below the method's own (strong order 1/2).
        Without noise the step is IsoMP's from the state, tolerance included, bit for bit.

        Parameters
        ----------
        problem : IsospectralProblem
            The problem the run integrates.

        Returns
        -------
        StochasticIsoMP
        """
        if not self._default_solver or self.update != "midpoint":
            return self
        noise = problem.noise
        alg = problem.algebra
        if noise is None or noise.dimension(alg) == 0 or not alg.closed_form_stage:
            return self
        return dataclasses.replace(self, solver=FixedPoint(rtol=CAYLEY_RTOL))

    @property
    def deterministic(self) -> IsoMP:
        """IsoMP from the state with this solver and update (the step on the field with
        noise)."""
        return IsoMP(solver=self.solver, initial_guess="state", update=self.update)

    def init(self, problem: IsospectralProblem, y0: Array, h: float) -> Any:
        """No state before the first step; the space is checked for the update.

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
            ``None``.

        Raises
        ------
        ParameterError
            ``update="cayley"`` on a space that is neither a dense matrix space (``so``,
            ``u``, ``su``, ``sym``, ``herm``) nor particles on ``(R^3, x)^N``.
        """
        self.check_space(problem.algebra)
        return None

    def check_space(self, algebra: Algebra) -> None:
        """Raise if the update cannot run on ``algebra`` (as
        :meth:`isoflow.IsoMP.check_space`).

        Parameters
        ----------
        algebra : Algebra
            The problem's state space.

        Raises
        ------
        ParameterError
            ``update="cayley"`` on a space without it (:func:`~isoflow.methods.isomp.cayley_space`).
        """
        check_update_space("StochasticIsoMP", self.update, algebra)

    def step_data(self, problem: IsospectralProblem, request: StepDataRequest) -> Array:
        """The increments ``(nsteps, members, D)`` of the request (``D`` Brownian motions,
        :meth:`TransportNoise.dimension <isoflow.noise.TransportNoise.dimension>`).

        Parameters
        ----------
        problem : IsospectralProblem
            The problem to advance.
        request : StepDataRequest
            The steps, the members and the step size the data are for.

        Returns
        -------
        ndarray, shape (nsteps, members, D)
        """
        return transport_increments(problem, request, self.truncation, self.substeps)

    def step(
        self, problem: IsospectralProblem, y: Array, h: float, state: Any = None,
        data: Array | None = None,
    ) -> StepResult:  # fmt: skip
        """One IsoMP step on the field with noise, from the state (no warm start).

        Parameters
        ----------
        problem : IsospectralProblem
            The problem to advance.
        y : ndarray, shape (*batch, *shape)
            The state at the start of the step.
        h : float
            The step size.
        state : object, optional
            Ignored (no state).
        data : ndarray, shape (*batch, D), optional
            The step's Brownian increments, as the time loop hands them (:meth:`step_data`);
            ``None`` draws those of the first step of the members ``0 .. M - 1`` (a step on its
            own).

        Returns
        -------
        StepResult
            The new state, the stage and the solve record.
        """
        noise = problem.noise
        base = self.deterministic
        if noise is None or noise.dimension(problem.algebra) == 0:
            return base.step(problem, y, h, None)
        alg = problem.algebra
        db = step_increments(self, problem, y, h, data)
        term = _noise_term(noise, alg, db, h)
        res = base.solver.solve(base.stage_problem(_without_jvp(problem, noise), y, h, term), y)
        if self.update == "cayley":
            self.check_space(alg)
            d = cayley_increment(alg, problem.evaluate_B(res.x) + term(res.x, None), y, h)
        else:
            d = h * res.aux
        return StepResult.from_solve(alg.project(y + d), res, None)


def check_substeps(substeps: Any) -> int:
    """``substeps`` as an int ``>= 1``, else a one-line :class:`ParameterError`."""
    if isinstance(substeps, bool) or not isinstance(substeps, (int, np.integer)) or substeps < 1:
        raise ParameterError(f"substeps must be an integer >= 1, got {substeps!r}")
    return int(substeps)


def transport_increments(
    problem: IsospectralProblem, request: StepDataRequest, truncation: float | None,
    substeps: int = 1,
) -> Array:  # fmt: skip
    """The increments ``(nsteps, members, D)`` of the problem's transport noise for
    ``request``, keyed by the members' ids (:class:`~isoflow.noise.TransportNoise`): the step
    data of every method for transport noise, so that they step on the same paths. With
    ``substeps = r``, step ``k``'s increments are the sums of those of the steps ``r (k - 1) +
    1 .. r k`` of size ``h / r``."""
    members = np.asarray(request.members, dtype=np.int64).reshape(-1)
    noise = problem.noise
    if noise is None:
        return np.zeros((request.nsteps, members.size, 0))
    keys = members
    if noise.members is not None:
        keys = np.where(members >= 0, noise.members[np.maximum(members, 0)], -1)
    r = substeps
    D = noise.dimension(problem.algebra)
    fine = brownian_increments(
        noise.seed, keys, request.k0 * r, request.nsteps * r, D, request.h / r,  # type: ignore[arg-type]
        stream=TRANSPORT_STREAM, truncation=truncation,
    )  # fmt: skip
    if r == 1:
        return fine
    return fine.reshape(request.nsteps, r, members.size, D).sum(axis=1)


def step_increments(
    method: Method, problem: IsospectralProblem, y: Array, h: float, data: Array | None
) -> Array:
    """The step's increments ``(*batch, D)``: ``data`` as the time loop hands it, or, for one
    step on its own (``iso.step``), those of the first step of the members ``0 .. M - 1``."""
    batch = problem.algebra.batch_shape(y)
    if data is None:
        M = int(np.prod(batch, dtype=np.int64))
        data = method.step_data(problem, StepDataRequest(0, 1, np.arange(M), h))[0]
    return np.asarray(data, dtype=np.float64).reshape(*batch, -1)


def _noise_term(
    noise: TransportNoise, alg: Algebra, db: Array, h: float
) -> Callable[[Array, Array | None], Array]:
    """``(X, mask) -> (1/h) sum_i dbeta_i B_i(X)`` for the members ``mask`` (constant fields:
    computed once)."""
    if callable(noise.fields):

        def term(X: Array, mask: Array | None) -> Array:
            return noise.increment(X, db if mask is None else db[mask], alg) / h

        return term
    fixed = noise.increment(np.zeros((*db.shape[:-1], *alg.shape), dtype=alg.dtype), db, alg) / h

    def constant(X: Array, mask: Array | None) -> Array:
        return fixed if mask is None else fixed[mask]

    return constant


def _without_jvp(problem: IsospectralProblem, noise: TransportNoise) -> IsospectralProblem:
    """The problem, without its ``B_jvp`` when the noise fields depend on the state."""
    if callable(noise.fields):
        return dataclasses.replace(problem, B_jvp=None)
    return problem


def refuse_noise(problem: IsospectralProblem, method: Method) -> None:
    """Raise if a method that does not integrate transport noise is given a problem with
    noise (a split step integrates it when its base does).

    Raises
    ------
    ParameterError
    """
    if problem.noise is not None and not method.integrates_noise:
        base = getattr(method, "base", method)  # a split step's
        cayley = getattr(base, "update", "midpoint") == "cayley"
        sto = "iso.StochasticIsoMP(update='cayley')" if cayley else "iso.StochasticIsoMP()"
        how = f"iso.Strang({sto})" if has_split_part(problem) else sto
        name = "stochastic-isomp-cayley" if cayley else "stochastic-isomp"
        raise ParameterError(
            f"the problem has transport noise, which {method.name} would ignore: integrate it "
            f"with {how} (method '{name}')"
        )
