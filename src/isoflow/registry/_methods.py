"""Methods and nonlinear solvers by name: :data:`METHODS`, :data:`SOLVERS` and their makers.

A method's name is its :attr:`isoflow.Method.name` (``isomp``, ``isosyrk-2``, the compositions
``<base>-<scheme>``); an implicit method takes one of the :data:`SOLVERS`, which are made
with a tolerance and, for the fixed point, an Anderson memory of at most
:data:`~isoflow.nonlinear.ANDERSON_MAX` (the bound :class:`isoflow.FixedPoint` checks; every
other check reads it).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ..methods import (
    RK4,
    ClassicalMidpoint,
    Composition,
    IsoMP,
    IsoSyRK,
    Method,
    SphericalMidpoint,
    StochasticHeun,
    StochasticIsoMP,
    Strang,
)
from ..methods.composition import SCHEMES
from ..methods.isomp import CAYLEY_RTOL
from ..nonlinear import ANDERSON_MAX, FixedPoint, Newton, NonlinearSolver
from ..problems import IsospectralProblem
from ..splitting import data_widths
from ._params import ConfigError, choice

__all__ = [
    "ANDERSON_MAX",
    "METHODS",
    "SOLVERS",
    "MethodSpec",
    "SolverSpec",
    "make_method",
    "make_solver",
    "split_method",
]


@dataclass(frozen=True)
class SolverSpec:
    """A nonlinear solver for implicit methods: ``make(rtol, anderson)``.

    Parameters
    ----------
    name : str
        The name on the command line and in configuration files.
    make : callable
        ``make(rtol, anderson) -> NonlinearSolver`` (``rtol=None``: the solver's default).
    description : str
        One line for ``isoflow list solvers``.
    anderson : bool
        Whether the solver takes Anderson mixing (default ``False``).
    """

    name: str
    make: Callable[[float | None, int], NonlinearSolver]
    description: str
    anderson: bool = False


def _fixed_point(rtol: float | None, anderson: int) -> NonlinearSolver:
    kw: dict[str, Any] = {} if rtol is None else {"rtol": rtol}
    return FixedPoint(anderson=anderson, **kw)


def _newton(jacobian: str) -> Callable[[float | None, int], NonlinearSolver]:
    def make(rtol: float | None, anderson: int) -> NonlinearSolver:
        kw: dict[str, Any] = {} if rtol is None else {"rtol": rtol}
        return Newton(jacobian=jacobian, **kw)  # type: ignore[arg-type]

    return make


#: Nonlinear solvers: name -> :class:`SolverSpec`.
SOLVERS: dict[str, SolverSpec] = {
    "fixed-point": SolverSpec(
        "fixed-point",
        _fixed_point,
        "fixed-point iteration (the default; anderson = m mixes the last m iterates)",
        anderson=True,
    ),
    "newton": SolverSpec("newton", _newton("dense"), "Newton, dense Jacobian (small spaces)"),
    "newton-krylov": SolverSpec(
        "newton-krylov", _newton("krylov"), "Newton-GMRES, matrix-free (large spaces)"
    ),
}


@dataclass(frozen=True)
class MethodSpec:
    r"""A time-stepping method: ``make(solver)``; ``implicit`` methods take a solver.

    Parameters
    ----------
    name : str
        The name on the command line and in configuration files.
    make : callable
        ``make(solver) -> Method`` (``solver`` is ``None`` for an explicit method).
    description : str
        One line for ``isoflow list methods``.
    implicit : bool
        Whether the method takes a nonlinear solver (default ``True``).
    default_rtol : float or None
        The solver tolerance a configuration without ``rtol`` gets (default ``None``: the
        solver's own; ``1e-8`` for ``isomp-cayley`` and ``stochastic-isomp-cayley``, whose update
        keeps the spectrum whatever the tolerance).
    solver_by_problem : bool
        Whether the method's default solver depends on the problem
        (:meth:`isoflow.Method.for_problem`): a configuration that sets no solver option
        (solver, ``rtol``, ``anderson``) then hands it none (``stochastic-isomp``: ``1e-8``
        with noise on :math:`(\mathbb{R}^3,\times)^N`, else ``1e-14``).
    """

    name: str
    make: Callable[[NonlinearSolver | None], Method]
    description: str
    implicit: bool = True
    default_rtol: float | None = None
    solver_by_problem: bool = False


def _composed(base: Callable[..., Method], scheme: str) -> Callable[[Any], Method]:
    return lambda solver: Composition(base(solver=solver), scheme)


def _plain(cls: Callable[..., Method]) -> Callable[[Any], Method]:
    return lambda solver: cls(solver=solver)


def _isosyrk(stages: int) -> Callable[[Any], Method]:
    return lambda solver: IsoSyRK(stages, solver=solver)


_BASES: dict[str, tuple[Callable[..., Method], str]] = {
    "isomp": (IsoMP, "isospectral minimal midpoint (the paper's method)"),
    "spherical-midpoint": (SphericalMidpoint, "spherical midpoint, (R^3, x)^N only"),
    "classical-midpoint": (ClassicalMidpoint, "classical implicit midpoint (not isospectral)"),
}

#: Methods: name -> :class:`MethodSpec`.
METHODS: dict[str, MethodSpec] = {
    **{name: MethodSpec(name, _plain(cls), text) for name, (cls, text) in _BASES.items()},
    "isomp-cayley": MethodSpec(
        "isomp-cayley",
        lambda solver: IsoMP(solver=solver or FixedPoint(rtol=CAYLEY_RTOL), update="cayley"),
        "IsoMP finished by the Cayley factor: isospectral to rounding at any tolerance (default "
        "rtol 1e-8); so, u, su, sym, herm, (R^3, x)^N",
        default_rtol=CAYLEY_RTOL,
    ),
    "rk4": MethodSpec("rk4", lambda solver: RK4(), "classical RK4 (explicit)", implicit=False),
    "stochastic-isomp": MethodSpec(
        "stochastic-isomp",
        _plain(StochasticIsoMP),
        "stochastic isospectral midpoint (models with noise or a temperature; default rtol "
        "1e-8 on spins and vortices, where it keeps |w_i| at any tolerance)",
        solver_by_problem=True,
    ),
    "stochastic-isomp-cayley": MethodSpec(
        "stochastic-isomp-cayley",
        lambda solver: StochasticIsoMP(
            solver=solver or FixedPoint(rtol=CAYLEY_RTOL), update="cayley"
        ),
        "stochastic IsoMP finished by the Cayley factor: isospectral to rounding at any "
        "tolerance (default rtol 1e-8); so, u, su, sym, herm, (R^3, x)^N",
        default_rtol=CAYLEY_RTOL,
    ),
    "stochastic-heun": MethodSpec(
        "stochastic-heun",
        lambda solver: StochasticHeun(),
        "stochastic Heun (explicit; not isospectral: a baseline for stochastic-isomp)",
        implicit=False,
    ),
    **{
        f"isosyrk-{s}": MethodSpec(
            f"isosyrk-{s}",
            _isosyrk(s),
            f"isospectral symplectic Gauss RK, {s} stage{'s' if s > 1 else ''}, order {2 * s}",
        )
        for s in (1, 2, 3)
    },
    **{
        f"{base}-{scheme}": MethodSpec(
            f"{base}-{scheme}",
            _composed(cls, scheme),
            f"{base} composed by {scheme} (order {SCHEMES[scheme][1]})",
        )
        for base, (cls, _text) in _BASES.items()
        for scheme in SCHEMES
    },
}


def make_solver(
    name: str = "fixed-point", *, rtol: float | None = None, anderson: int = 0
) -> NonlinearSolver:
    """The nonlinear solver called ``name`` (:data:`SOLVERS`).

    Parameters
    ----------
    name : str
        ``"fixed-point"`` (default), ``"newton"`` or ``"newton-krylov"``.
    rtol : float, optional
        Relative tolerance (default: the solver's own).
    anderson : int
        Anderson memory of the fixed-point solver (default 0: none).

    Returns
    -------
    NonlinearSolver

    Raises
    ------
    ConfigError
        An unknown name, or ``anderson`` for a solver other than the fixed-point one.
    """
    spec = SOLVERS[choice(name, SOLVERS, "solver")]
    if anderson and not spec.anderson:
        raise ConfigError(f"anderson mixing is an option of the fixed-point solver, not {name!r}")
    return spec.make(rtol, anderson)


def make_method(name: str, solver: NonlinearSolver | None = None) -> Method:
    """The method called ``name`` (:data:`METHODS`) with ``solver`` (default: fixed point, or
    the method's own default when it depends on the problem, :attr:`MethodSpec.
    solver_by_problem`)."""
    spec = METHODS[choice(name, METHODS, "method")]
    if not spec.implicit:
        if solver is not None:
            raise ConfigError(f"method {name!r} is explicit: it takes no nonlinear solver")
        return spec.make(None)
    if solver is None and spec.solver_by_problem:
        return spec.make(None)
    return spec.make(solver if solver is not None else FixedPoint())


def split_method(method: Method, problem: IsospectralProblem) -> Method:
    """The split step of ``method`` for a problem with a linear part or forcing:
    ``Strang(method)``, and for a composition the composition of the split step
    (``Composition(Strang(base), scheme)``, of the composition's order) unless the forcing has
    step data (time-dependent amplitudes, noise), which belong to whole steps."""
    if isinstance(method, Composition) and sum(data_widths(problem)) == 0:
        return Composition(Strang(method.base), method.scheme)
    return Strang(method)
