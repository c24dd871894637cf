r"""The Strang split step's compiled stage: IsoMP between two half steps of the linear part and
the forcing (:class:`isoflow.Strang`, :mod:`isoflow.splitting`).

``begin`` applies the first half step :math:`S_{h/2}` to the state before the solve, ``finish``
IsoMP's finish and then the second half step to the new state; the iteration is IsoMP's (on the
BLAS layout its specializations: :mod:`isoflow._compiled.dense_tiles` with
:func:`finish_tiles`, and for large complex states :mod:`isoflow._compiled.dense_planar` with
:func:`finish_planar`). A half step is

* the exact flow of the linear part, :func:`apply_flow`, dispatched on the class of its record:
  :class:`ModalFlow` (a basis you give, any layout whose unit is one member) and
  :class:`UniformFlow` (one rate on every mode: a scaling) here, the
  sphere's per-diagonal flow (:class:`isoflow.sphere.compiled.SphereFlow`) registered by
  :mod:`isoflow.sphere.compiled` with :func:`provide_flow`;
* the forcing, patterns stored sparse (CSR: a band of spherical harmonics touches two
  diagonals) with their values per half-step length, times an amplitude that is ``1`` (steady)
  or a column of the step data (a time-dependent amplitude, a noise normal).

The method's parameters (a flat record such as :class:`SplitNoFlow`) hold every half-step
length of the run (one per distinct substep of a composition); ``begin`` and ``finish`` find
theirs by ``h / 2``.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any, NamedTuple

import numba
import numpy as np
from numba.core import errors as numba_errors
from numba.extending import overload
from numpy.typing import NDArray

from .. import blocks, cayley, dense_planar, dense_tiles

__all__ = [
    "SPLIT_FIELDS",
    "ModalFlow",
    "NoFlow",
    "SplitModalFlow",
    "SplitNoFlow",
    "SplitUniformFlow",
    "UniformFlow",
    "apply_flow",
    "begin",
    "finish",
    "finish_cayley_planar",
    "finish_cayley_tiles",
    "finish_planar",
    "finish_tiles",
    "params",
    "provide_flow",
]

Array = NDArray[Any]


class NoFlow(NamedTuple):
    """No linear part (a forcing alone)."""

    none: int


class UniformFlow(NamedTuple):
    """:math:`W \\mathrel{*}= e^{-c\\tau}`: a linear part with one rate ``c`` on every mode
    (a linear drag alone, or no dissipation with a forcing); ``decay[j_tau] = e^{-c tau}``."""

    decay: Array


class ModalFlow(NamedTuple):
    """:math:`W \\mathrel{+}= \\sum_j (e^{-c_j\\tau} - 1)\\langle e_j, W\\rangle e_j`: the basis
    ``(r, S)`` (flat, the state's dtype) and ``decay[j_tau, j] = e^{-c_j tau} - 1``."""

    basis: Array
    decay: Array


#: The split stage's own parameters, the leading fields of every flat parameter record:
#: ``taus`` the half-step lengths; the forcing patterns in CSR form (``indptr``, ``idx``) with
#: ``val[j_tau, k]``; ``amp[p, half]`` the step-data column of pattern ``p``'s amplitude in the
#: first or second half step (``-1``: ``1``).
SPLIT_FIELDS = ("taus", "indptr", "idx", "val", "amp")


class SplitNoFlow(NamedTuple):
    """The split stage's parameters (the ``mp`` of the stage interface) with :class:`NoFlow`.

    Each flow record class has such a flat record: :data:`SPLIT_FIELDS`, then the flow's own
    fields. Flat, because numba's parallel driver passes a tuple's arrays to its threads one
    by one and cannot pass a tuple nested in one (a nested flow record made every ensemble of
    a split step fail to compile with ``threads`` above 1); the flow's implementation reads
    its fields from the flat record by name."""

    taus: Array
    indptr: Array
    idx: Array
    val: Array
    amp: Array
    none: int


class SplitUniformFlow(NamedTuple):
    """:class:`SplitNoFlow` for :class:`UniformFlow`."""

    taus: Array
    indptr: Array
    idx: Array
    val: Array
    amp: Array
    decay: Array


class SplitModalFlow(NamedTuple):
    """:class:`SplitNoFlow` for :class:`ModalFlow`."""

    taus: Array
    indptr: Array
    idx: Array
    val: Array
    amp: Array
    basis: Array
    decay: Array


class SplitParams(NamedTuple):
    """The nested parameter record of isoflow before the flat ones; not used. Kept because
    numba unpickles a cache index (whose entries name the types of compiled signatures)
    before it checks the source's stamp, so an index written by an earlier version would
    otherwise fail to load instead of being recompiled."""

    taus: Array
    flow: Any
    indptr: Array
    idx: Array
    val: Array
    amp: Array


#: flat parameter record class -> compiled implementation ``impl(flow, W, j)`` of its flow
_FLOWS: dict[type, Any] = {}
#: flow record class -> its flat parameter record class
_FLAT: dict[type, type] = {}


def provide_flow(cls: type, flat: type) -> Callable[[Any], Any]:
    """Register the decorated compiled function ``impl(flow, W, j)`` (the flow of half step
    ``j`` on the flat state ``W``) for the flow record class ``cls``, whose runs pass the flat
    record class ``flat`` (:data:`SPLIT_FIELDS`, then ``cls``'s fields; see
    :class:`SplitNoFlow`). ``impl`` gets the flat record and reads ``cls``'s fields by name.

    Raises
    ------
    TypeError
        ``flat`` does not have exactly those fields.
    """
    want = SPLIT_FIELDS + tuple(getattr(cls, "_fields", ()))
    if tuple(getattr(flat, "_fields", ())) != want:
        raise TypeError(f"{flat.__name__} must be a NamedTuple with the fields {want}")

    def register(impl: Any) -> Any:
        _FLOWS[flat] = impl
        _FLAT[cls] = flat
        return impl

    return register


def apply_flow(flow: Any, W: Any, j: Any) -> None:
    """The linear part's flow over half step ``j`` on the flat state ``W``, ``flow`` the
    stage's flat parameter record (compiled only)."""
    raise NotImplementedError("apply_flow is compiled: call it from numba code")


_FORWARDERS: dict[type, Callable[..., Any]] = {}


@overload(apply_flow)
def _apply_flow_typer(flow, W, j):  # type: ignore[no-untyped-def]  # numba: no annotations
    cls = getattr(flow, "instance_class", None)
    impl = _FLOWS.get(cls) if cls is not None else None
    if impl is None:
        raise numba_errors.TypingError(f"no compiled flow for the split parameters {flow}")
    fwd = _FORWARDERS.get(cls)  # type: ignore[arg-type]
    if fwd is None:  # a plain function calling impl (what overload wants)
        params = ", ".join(inspect.signature(apply_flow).parameters)
        namespace: dict[str, Any] = {"impl": impl}
        exec(f"def forward({params}):\n    return impl({params})\n", namespace)
        fwd = _FORWARDERS[cls] = namespace["forward"]  # type: ignore[index]
    return fwd


@provide_flow(NoFlow, SplitNoFlow)
@numba.njit(cache=True)
def _no_flow(flow, W, j):  # type: ignore[no-untyped-def]
    pass


@provide_flow(UniformFlow, SplitUniformFlow)
@numba.njit(cache=True)
def _uniform_flow(flow, W, j):  # type: ignore[no-untyped-def]
    d = flow.decay[j]
    if d != 1.0:
        for i in range(W.shape[0]):
            W[i] = complex(d * W[i].real, d * W[i].imag)


@provide_flow(ModalFlow, SplitModalFlow)
@numba.njit(cache=True)
def _modal_flow(flow, W, j):  # type: ignore[no-untyped-def]
    E = flow.basis
    for p in range(E.shape[0]):
        e = E[p]
        acc = 0.0
        for i in range(W.shape[0]):
            acc += e[i].real * W[i].real + e[i].imag * W[i].imag
        g = flow.decay[j, p] * acc
        for i in range(W.shape[0]):
            W[i] += g * e[i]


@numba.njit(cache=True, inline="always")
def _tau_index(taus, tau):  # type: ignore[no-untyped-def]
    for j in range(taus.shape[0]):
        if taus[j] == tau:
            return j
    return 0


@numba.njit(cache=True)
def _half_step(mp, sd, W, h, half):  # type: ignore[no-untyped-def]
    """The flow and the forcing of a half step ``h / 2`` on ``W`` (``half``: 0 or 1)."""
    j = _tau_index(mp.taus, 0.5 * h)
    apply_flow(mp, W, j)
    val = mp.val[j]
    for p in range(mp.indptr.shape[0] - 1):
        col = mp.amp[p, half]
        a = 1.0 if col < 0 else sd[0, col]
        for k in range(mp.indptr[p], mp.indptr[p + 1]):
            W[mp.idx[k]] += a * val[k]


@numba.njit(cache=True)
def begin(f, fargs, lay, mp, sd, W, work, h):  # type: ignore[no-untyped-def]
    """The first half step, before the solve."""
    _half_step(mp, sd, W, h, 0)


@numba.njit(cache=True)
def finish(f, fargs, lay, mp, sd, W, X, aux, work, h, E, Wn, fin):  # type: ignore[no-untyped-def]
    """IsoMP's new state, then the second half step."""
    blocks.advance_state(lay, W, h, aux, E, Wn, fin)
    _half_step(mp, sd, Wn, h, 1)


@numba.njit(cache=True)
def finish_tiles(f, fargs, lay, mp, sd, W, X, aux, work, h, E, Wn, fin):  # type: ignore[no-untyped-def]
    """:func:`finish` after IsoMP's fused BLAS finish (:mod:`isoflow._compiled.dense_tiles`)."""
    dense_tiles.finish(f, fargs, lay, mp, sd, W, X, aux, work, h, E, Wn, fin)
    _half_step(mp, sd, Wn, h, 1)


@numba.njit(cache=True)
def finish_planar(f, fargs, lay, mp, sd, W, X, aux, work, h, E, Wn, fin):  # type: ignore[no-untyped-def]
    """:func:`finish` after IsoMP's finish in real planes (:mod:`isoflow._compiled.dense_planar`,
    large complex states)."""
    dense_planar.finish(f, fargs, lay, mp, sd, W, X, aux, work, h, E, Wn, fin)
    _half_step(mp, sd, Wn, h, 1)


def _values_on(nz: Array, row: Any) -> Array:
    """The values of the sparse one-row matrix ``row`` at the sorted flat indices ``nz``
    (a superset of its own), zero elsewhere."""
    out = np.zeros(nz.size, dtype=row.dtype)
    out[np.searchsorted(nz, row.indices)] = row.data
    return out


def params(method: Any, problem: Any, layout: Any, steps: tuple[float, ...]) -> Any:
    """The stage's parameters for the substep lengths ``steps`` of a run of ``problem`` (on a
    layout of one member per unit in the state's own order: ``layout`` is not read)."""
    alg = problem.algebra
    taus = tuple(dict.fromkeys(0.5 * float(s) for s in steps))
    lin = problem.linear_part
    flow = lin.compiled(taus, alg) if lin is not None else NoFlow(0)
    halves = [method.half(problem, t) for t in taus]
    rd = 0 if halves[0].responses is None else len(halves[0].responses)
    rs = 0 if halves[0].noise is None else halves[0].noise.shape[0]
    patterns: list[list[Array]] = []  # per pattern, its flat values per tau
    amp: list[tuple[int, int]] = []
    if halves[0].steady is not None:
        patterns.append([np.asarray(t.steady).reshape(-1) for t in halves])
        amp.append((-1, -1))
    for p in range(rd):
        patterns.append([np.asarray(t.responses)[p].reshape(-1) for t in halves])
        amp.append((p, rd + rs + p))
    indptr = [0]
    idx: list[Array] = []
    vals: list[Array] = []
    for per_tau in patterns:
        nz = np.flatnonzero(np.any(np.stack(per_tau) != 0, axis=0))
        idx.append(nz)
        vals.append(np.stack([v[nz] for v in per_tau]))
        indptr.append(indptr[-1] + nz.size)
    for p in range(rs):  # the noise modes are sparse already (the same entries for each tau)
        rows = [t.noise[[p]] for t in halves]
        nz = np.unique(np.concatenate([r.indices for r in rows]))
        idx.append(nz)
        vals.append(np.stack([_values_on(nz, r) for r in rows]))
        indptr.append(indptr[-1] + nz.size)
        amp.append((rd + p, rd + rs + rd + p))
    ntau = len(taus)
    flat = _FLAT.get(type(flow))
    if flat is None:
        raise TypeError(f"no compiled flow registered for {type(flow).__name__} (provide_flow)")
    return flat(  # type: ignore[no-any-return]
        np.asarray(taus, dtype=np.float64),
        np.asarray(indptr, dtype=np.int64),
        np.concatenate(idx).astype(np.int64) if idx else np.zeros(0, dtype=np.int64),
        np.ascontiguousarray(
            np.concatenate(vals, axis=1) if vals else np.zeros((ntau, 0)), dtype=alg.dtype
        ),
        np.asarray(amp, dtype=np.int64).reshape(-1, 2),
        *flow,
    )


@numba.njit(cache=True)
def finish_cayley_tiles(f, fargs, lay, mp, sd, W, X, aux, work, h, E, Wn, fin):  # type: ignore[no-untyped-def]
    """:func:`finish` after the Cayley update on complex tiles or real states
    (:func:`isoflow._compiled.cayley.finish_tiles`)."""
    cayley.finish_tiles(f, fargs, lay, mp, sd, W, X, aux, work, h, E, Wn, fin)
    _half_step(mp, sd, Wn, h, 1)


@numba.njit(cache=True)
def finish_cayley_planar(f, fargs, lay, mp, sd, W, X, aux, work, h, E, Wn, fin):  # type: ignore[no-untyped-def]
    """:func:`finish` after the Cayley update in real planes
    (:func:`isoflow._compiled.cayley.finish_planar`)."""
    cayley.finish_planar(f, fargs, lay, mp, sd, W, X, aux, work, h, E, Wn, fin)
    _half_step(mp, sd, Wn, h, 1)
