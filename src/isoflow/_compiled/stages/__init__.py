"""The compiled stages of the methods, and the registry that gives a method its stage.

A *stage* is one method's fixed-point iteration and finish, written once against the layout
blocks (:mod:`isoflow._compiled.blocks`) with the interface of the one driver
(:mod:`isoflow._compiled.driver`)::

    iterate(f, fargs, lay, mp, sd, W, X, G, aux, work, h, rr)   # G = G(X), rr per lane
    finish(f, fargs, lay, mp, sd, W, X, aux, work, h, E, Wn, fin)  # the new state, fin per lane
    begin(f, fargs, lay, mp, sd, W, work, h)                    # optional, before each solve

``f, fargs`` are the kernel's field, ``lay`` the layout record, ``mp`` the method's parameters
(a tuple, :attr:`CompiledStage.params`), ``sd`` the unit's step data ``(L, D)`` (e.g. noise
increments; ``D = 0`` for most methods), ``h`` the (sub)step, ``work`` the scratch rows,
``E`` the compensation of the update (empty when the method does not compensate; see
:attr:`CompiledStage.compensated`). A method joins the compiled paths by one call of
:func:`register`; a layout that needs a fused evaluation of a stage for speed gets a named
:class:`Specialization` (with the benchmark that justifies it). A stage runs on every layout
that provides the blocks it :attr:`needs <CompiledStage.needs>`; compositions of the method
(:class:`isoflow.Composition`) run it substep by substep.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from ...methods import IsoMP, SphericalMidpoint, StochasticIsoMP, Strang
from ...methods._base import StepDataRequest
from ...splitting import data_widths
from .. import (
    cayley,
    cayley_small,  # noqa: F401  (the small layouts' cayley_increment block)
    dense_planar,
    dense_tiles,
    spin_chain,
)
from ..dense import DenseBlas
from ..layout import Layout
from ..spin_chain import CHAIN_RECORDS
from . import isomp, spherical_midpoint, split, stochastic_isomp

__all__ = [
    "CompiledStage",
    "Specialization",
    "StageOnLayout",
    "StepDataRequest",
    "register",
    "stage_for",
]


@dataclass(frozen=True)
class Specialization:
    """A fused evaluation of a stage on one layout, kept because a benchmark shows it pays.

    Attributes
    ----------
    choose : callable
        ``layout -> (iterate, finish)`` (e.g. the serial or threaded sweeps).
    nwork : int or callable
        Scratch rows per unit, or ``layout -> rows`` when they depend on the choice.
    why : str
        The benchmark that justifies it.
    """

    choose: Callable[[Layout], tuple[Any, Any]]
    nwork: int | Callable[[Layout], int]
    why: str

    def rows(self, layout: Layout) -> int:
        """Scratch rows per unit on ``layout``."""
        return self.nwork(layout) if callable(self.nwork) else self.nwork


def _on_chains(spec: Specialization) -> dict[type, Specialization]:
    """``spec`` for every record class of the spin chain's layout (with and without damping)."""
    return dict.fromkeys(CHAIN_RECORDS, spec)


@dataclass(frozen=True)
class StageOnLayout:
    """A stage's functions on one layout (what the driver is given)."""

    begin: Any
    iterate: Any
    finish: Any
    nwork: int
    begin_moves_state: bool = True


def _no_offsets(method: Any, problem: Any) -> int:
    return 0


def _interpolating(method: Any, problem: Any) -> int | None:
    return None


def _no_fallback(method: Any, problem: Any) -> int:
    return 0


def _no_params(
    method: Any, problem: Any, layout: Layout, steps: tuple[float, ...]
) -> tuple[Any, ...]:
    return ()


def _always(*args: Any) -> bool:
    return True


def _not_compensated(method: Any) -> bool:
    return False


def _method_step_data(method: Any, problem: Any, request: StepDataRequest) -> Any:
    """The step data of a method that reads some (:meth:`isoflow.Method.step_data`): the
    compiled and the NumPy paths read the same."""
    return method.step_data(problem, request)


@dataclass(frozen=True)
class CompiledStage:
    """A method's compiled stage.

    Attributes
    ----------
    name : str
    iterate, finish : numba dispatchers
        The stage, written against the blocks.
    needs : frozenset of str
        The blocks it calls (a layout without one of them gives no compiled path).
    nwork : int
        Scratch rows per unit.
    offsets : callable
        ``(method, problem) -> int``: stage offsets kept for the extrapolated initial guess
        (the order may depend on the problem's space; ``0``: the solve starts from the
        state). The method state is then ``(h, D_1, D_2, ...)``, newest
        first, as :class:`isoflow.IsoMP` keeps it.
    start_degree : callable
        ``(method, problem) -> int or None``: the degree of the polynomial the start fits to
        the offsets (least squares once there are more than ``degree + 1``,
        :func:`isoflow.methods.extrapolation.start_weights`); ``None``: interpolation
        through all of them.
    start_fallback : callable
        ``(method, problem) -> int``: offsets of the interpolating start that a fitted one
        takes instead whenever it would have predicted the newest offset within half the
        tolerance (:func:`isoflow._compiled.flat.guess_or_fit`); 0: never.
    params : callable
        ``(method, problem, layout, steps) -> tuple``: the method's parameters as the stage
        reads them (arrays in the layout's units), for a run whose substeps have the lengths
        ``steps`` (one, unless composed).
    begin : numba dispatcher or None
        An explicit part before each solve (a split step's half flow, the stochastic step's
        noise term in a scratch row), or none.
    begin_moves_state : bool
        Whether ``begin`` changes the state (a split step's half flow). ``False`` when it only
        fills scratch rows (the stochastic step's noise term): the driver then keeps no copy
        of the state a step starts from, and a single system's step swaps its two state
        buffers instead of copying the new state back.
    step_data : callable or None
        ``(method, problem, request) -> (nsteps, members, D)`` float array: what the stage
        reads per step and member (``sd`` of the interface, e.g. noise increments; row ``i``
        of the result is the member ``request.members[i]``), made by the time loop for each
        chunk (:class:`StepDataRequest`). ``None``: the stage reads none (``D = 0``). It must
        depend only on the method, the problem, the step and the member, never on how a run is
        cut into chunks, so that a resumed or split run draws the same data.
    applies : callable
        ``(method, problem, composed) -> bool``: whether the stage runs this method on this
        problem (e.g. the split stage runs ``Strang(IsoMP())`` only, and not composed when
        its step data belong to whole steps).
    accepts : callable
        ``layout -> bool``: whether the stage runs on a layout (beyond the blocks it needs).
    compensated : callable
        ``method -> bool``: whether the method compensates its update (the driver then
        keeps a compensation per unit and substep position, and the method state carries
        it, :func:`isoflow.methods.isomp.pack_state`).
    specializations : dict
        Layout record class -> :class:`Specialization`.
    """

    name: str
    iterate: Any
    finish: Any
    needs: frozenset[str]
    nwork: int
    offsets: Callable[[Any, Any], int] = _no_offsets
    start_degree: Callable[[Any, Any], int | None] = _interpolating
    start_fallback: Callable[[Any, Any], int] = _no_fallback
    params: Callable[[Any, Any, Layout, tuple[float, ...]], tuple[Any, ...]] = _no_params
    begin: Any = None
    begin_moves_state: bool = True
    step_data: Callable[[Any, Any, StepDataRequest], Any] | None = None
    compensated: Callable[[Any], bool] = _not_compensated
    applies: Callable[[Any, Any, bool], bool] = _always
    accepts: Callable[[Layout], bool] = _always
    specializations: dict[type, Specialization] = field(default_factory=dict)

    def on(self, layout: Layout) -> StageOnLayout | None:
        """The stage's functions on ``layout``, or ``None`` if it lacks a block."""
        if not self.accepts(layout):
            return None
        spec = self.specializations.get(type(layout.record))
        if spec is not None:
            it, fin = spec.choose(layout)
            return StageOnLayout(self.begin, it, fin, spec.rows(layout), self.begin_moves_state)
        if not self.needs <= layout.blocks:
            return None
        return StageOnLayout(
            self.begin, self.iterate, self.finish, self.nwork, self.begin_moves_state
        )


#: Method class -> its compiled stage.
_STAGES: dict[type, CompiledStage] = {}


def register(method: type, stage: CompiledStage) -> None:
    """Give the method class ``method`` (exactly that class) the compiled ``stage``."""
    _STAGES[method] = stage


def _cayley(method: Any) -> bool:
    return type(method) is IsoMP and method.update == "cayley"


def stage_for(method: Any) -> CompiledStage | None:
    """The compiled stage of ``method`` (an instance), or ``None``."""
    if _cayley(method):
        return _ISOMP_CAYLEY
    if type(method) is StochasticIsoMP and method.update == "cayley":
        return _STOCHASTIC_CAYLEY
    if type(method) is Strang and _cayley(method.base):
        return _SPLIT_CAYLEY
    return _STAGES.get(type(method))


def _on_blas(
    planar: tuple[Any, Any], tiles: tuple[Any, Any]
) -> Callable[[Layout], tuple[Any, Any]]:
    """A stage's ``(iterate, finish)`` on the BLAS layout: ``planar`` for complex states from
    ``n = PLANAR_MIN_N`` (real planes, 3M products), else ``tiles``."""

    def choose(layout: Layout) -> tuple[Any, Any]:
        return planar if layout.record.planar else tiles

    return choose


def _dense_blas_rows(layout: Layout) -> int:
    return dense_planar.NWORK if layout.record.planar else dense_tiles.NWORK


def _isomp_offsets(method: IsoMP, problem: Any) -> int:
    if method.initial_guess != "extrapolate":
        return 0
    return method.window_for(problem.algebra)


def _isomp_degree(method: IsoMP, problem: Any) -> int:
    return method.order_for(problem.algebra)


def _isomp_fallback(method: IsoMP, problem: Any) -> int:
    return method.fallback_for(problem.algebra)


def _smm_offsets(method: SphericalMidpoint, problem: Any) -> int:
    return 1 if method.initial_guess == "extrapolate" else 0


register(
    IsoMP,
    CompiledStage(
        "IsoMP",
        isomp.iterate,
        isomp.finish,
        frozenset({"evaluate_B", "stage_map", "advance_state"}),
        isomp.NWORK,
        offsets=_isomp_offsets,
        start_degree=_isomp_degree,
        start_fallback=_isomp_fallback,
        compensated=lambda method: bool(method.compensated),
        specializations={
            DenseBlas: Specialization(
                _on_blas(
                    (dense_planar.iterate, dense_planar.finish),
                    (dense_tiles.iterate, dense_tiles.finish),
                ),
                _dense_blas_rows,
                "benchmarks 3, 10, 12: the triangular product and one tile pass; complex "
                "states from n = PLANAR_MIN_N in real planes with 3M products (benchmark 12)",
            ),
            **_on_chains(
                Specialization(
                    spin_chain.isomp_sweeps,
                    1,
                    "benchmarks 4, 5: one fused memory sweep",
                )
            ),
        },
    ),
)


def _with_cayley_finish(
    stage: CompiledStage, name: str, finishes: tuple[Any, Any], why: str,
    iterates: tuple[Any, Any] = (dense_planar.iterate, dense_tiles.iterate),
    rows: Callable[[Layout], int] = _dense_blas_rows,
    blocks_finish: Any = None,
    chain: Specialization | None = None,
) -> CompiledStage:  # fmt: skip
    """``stage`` with the Cayley update's finishes ``(planar, tiles)`` after the BLAS
    iterations ``iterates`` (``(planar, tiles)``, IsoMP's by default, with ``rows`` scratch
    rows) on the BLAS layout (the finish inverts with LAPACK). With ``blocks_finish``, also on
    the layouts that provide the ``cayley_increment`` block (small dense states and their
    lanes, particles), after the stage's own iteration, and with ``chain`` (a
    :class:`Specialization` with the Cayley finish) on the spin chain's fused sweeps;
    elsewhere the run takes the NumPy path (the split step on small states)."""
    planar, tiles = finishes
    iterate_planar, iterate_tiles = iterates
    specializations: dict[type, Specialization] = {
        DenseBlas: Specialization(
            _on_blas((iterate_planar, planar), (iterate_tiles, tiles)), rows, why
        ),
    }
    if chain is not None:
        specializations |= _on_chains(chain)
    needs = {"evaluate_B", "stage_map", "advance_state"}
    needs.add("cayley_increment" if blocks_finish is not None else "(BLAS layout only)")
    return dataclasses.replace(
        stage,
        name=name,
        finish=blocks_finish if blocks_finish is not None else stage.finish,
        needs=frozenset(needs),
        specializations=specializations,
    )


#: ``IsoMP(update="cayley")``: IsoMP's stage with another finish.
_ISOMP_CAYLEY = _with_cayley_finish(
    _STAGES[IsoMP],
    "Cayley update",
    (cayley.finish_planar, cayley.finish_tiles),
    "IsoMP's iteration (benchmarks 3, 10, 12); the Cayley finish pays at small N (benchmark 22)",
    blocks_finish=cayley.finish_blocks,
    chain=Specialization(
        spin_chain.isomp_cayley_sweeps,
        1,
        "the chain's fused sweeps (benchmarks 4, 5), the Cayley finish a step",
    ),
)

register(
    SphericalMidpoint,
    CompiledStage(
        "spherical midpoint",
        spherical_midpoint.iterate,
        spherical_midpoint.finish,
        frozenset({"spherical_point", "evaluate_B", "bracket", "stage_update1", "advance_state"}),
        spherical_midpoint.NWORK,
        offsets=_smm_offsets,
        specializations={
            **_on_chains(
                Specialization(
                    spin_chain.spherical_sweeps,
                    2,
                    "benchmark 5: fused memory sweeps",
                )
            ),
        },
    ),
)


def _split_applies(method: Strang, problem: Any, composed: bool) -> bool:
    """``Strang(IsoMP())`` (either update: :func:`stage_for` picks the stage of the base's);
    composed only when its step data are empty (steady forcing)."""
    if type(method.base) is not IsoMP:
        return False
    return not composed or sum(data_widths(problem)) == 0


register(
    Strang,
    CompiledStage(
        "Strang split",
        isomp.iterate,
        split.finish,
        frozenset({"evaluate_B", "stage_map", "advance_state"}),
        isomp.NWORK,
        offsets=lambda method, problem: _isomp_offsets(method.base, problem),
        start_degree=lambda method, problem: _isomp_degree(method.base, problem),
        start_fallback=lambda method, problem: _isomp_fallback(method.base, problem),
        params=split.params,
        begin=split.begin,
        step_data=_method_step_data,
        compensated=lambda method: bool(method.base.compensated),
        applies=_split_applies,
        accepts=lambda layout: layout.lanes == 1 and layout.identity,
        specializations={
            DenseBlas: Specialization(
                _on_blas(
                    (dense_planar.iterate, split.finish_planar),
                    (dense_tiles.iterate, split.finish_tiles),
                ),
                _dense_blas_rows,
                "IsoMP's (benchmarks 3, 10, 12); the split step's cost: benchmark 15",
            ),
        },
    ),
)


def _stochastic_blas_rows(layout: Layout) -> int:
    """IsoMP's BLAS rows and the noise term's (the last)."""
    return _dense_blas_rows(layout) + 1


register(
    StochasticIsoMP,
    CompiledStage(
        "stochastic IsoMP",
        stochastic_isomp.iterate,
        isomp.finish,
        frozenset({"evaluate_B", "stage_map", "advance_state"}),
        stochastic_isomp.NWORK,
        params=stochastic_isomp.noise_params,
        begin=stochastic_isomp.begin,
        begin_moves_state=False,  # the noise term, into a scratch row
        step_data=_method_step_data,
        applies=lambda method, problem, composed: (
            not composed and stochastic_isomp.compiled_noise(problem)
        ),
        specializations={
            DenseBlas: Specialization(
                _on_blas(
                    (stochastic_isomp.iterate_planar, dense_planar.finish),
                    (stochastic_isomp.iterate_tiles, dense_tiles.finish),
                ),
                _stochastic_blas_rows,
                "IsoMP's iteration (benchmarks 3, 10, 12) on the field with the noise",
            ),
            **_on_chains(
                Specialization(
                    spin_chain.stochastic_sweeps,
                    spin_chain.STO_NWORK,
                    "benchmark 18: IsoMP's fused sweep with the step's noise term",
                )
            ),
        },
    ),
)

#: ``Strang(IsoMP(update="cayley"))``: the split stage with the Cayley finish.
_SPLIT_CAYLEY = _with_cayley_finish(
    _STAGES[Strang],
    "Strang split, Cayley update",
    (split.finish_cayley_planar, split.finish_cayley_tiles),
    "the split step's (benchmark 15) with the Cayley finish (benchmark 22)",
)

#: ``StochasticIsoMP(update="cayley")``: the stochastic stage with the Cayley finish (the
#: finishes read ``B~``, the field with the noise, where IsoMP's leave ``B``).
_STOCHASTIC_CAYLEY = _with_cayley_finish(
    _STAGES[StochasticIsoMP],
    "stochastic IsoMP, Cayley update",
    (cayley.finish_planar, cayley.finish_tiles),
    "the stochastic stage's BLAS iteration with the Cayley finish (benchmark 22)",
    iterates=(stochastic_isomp.iterate_planar, stochastic_isomp.iterate_tiles),
    rows=_stochastic_blas_rows,
    blocks_finish=cayley.finish_blocks,
    chain=Specialization(
        spin_chain.stochastic_cayley_sweeps,
        spin_chain.STO_NWORK,
        "the chain's fused sweeps (benchmark 18), the Cayley finish a step",
    ),
)
