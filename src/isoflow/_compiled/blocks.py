r"""The building blocks a state layout supplies, and how a compiled stage calls them.

A *layout* is how the states of a run sit in memory for the compiled loops (a dense matrix, an
``(N, 3)`` particle array, a spin chain in a ``(3, N)`` layout, a block of ensemble members
interleaved as SIMD lanes). Its parameters travel as a *layout record*, a named tuple whose
class names the layout (:class:`DenseSmall`, ...). A compiled *stage* (one method's iteration
and finish, :mod:`isoflow._compiled.stages`) is written once against the blocks below; numba
resolves every block call by the class of the record when it compiles the stage for a layout,
so the layout's code is inlined and the stage is written only once.

Every buffer is the flat state of one *unit*: one ensemble member, or for a layout with
``L > 1`` lanes, ``L`` members interleaved (:func:`lanes`). Per-lane outputs (residuals,
finiteness) are arrays of length ``L``.

The blocks (a layout provides those its stages need; the stage registry checks this):

``lanes(lay)``
    Members per unit (``1`` unless the layout interleaves members).
``evaluate_B(lay, f, fargs, X, B)``
    ``B = B(X)``: the kernel's field ``f(X, B, *fargs)`` on the unit's views (a layout may form
    ``B`` itself instead, e.g. the point-vortex pair sum).
``bracket_triple(lay, B, X, C, T)``
    ``C = [B, X]`` and ``T = B X B`` (``T`` in the space up to rounding).
``bracket(lay, B, X, C)``
    ``C = [B, X]`` alone.
``stage_update(lay, W, a, C, b, T, G, X, rr)``
    :math:`G = \Pi(W + a C + b T)` onto the stage space; ``rr[q] = |G - X|^2`` per lane.
``stage_update1(lay, W, a, C, G, X, rr)``
    The same without ``T``: :math:`G = \Pi(W + a C)`.
``stage_map(lay, W, h, B, X, G, C, T, rr)``
    IsoMP's stage map for the field ``B``: ``G`` and the bracket ``C`` the step's finish adds
    (:math:`W_{k+1} = \Pi_V(W + h C)`), ``T`` scratch, ``rr[q] = |G - X|^2``. Generic
    (:func:`provide_generic_stage_map`): ``C = [B, X]``, ``T = B X B`` and
    :math:`G = \Pi(W + \tfrac h2 C + \tfrac{h^2}{4} T)`. On :math:`(\mathbb{R}^3,\times)^N`
    the stage of each particle for a given field is solved in closed form
    (:func:`isoflow._compiled.particles.so3_stage`): :math:`g_i = (w_i + u_i \times w_i) /
    (1 + |u_i|^2)`, :math:`u_i = \tfrac h2 b_i`, and ``C_i = b_i x g_i``, so that the finish
    rotates every ``w_i``.
``advance_state(lay, W, h, C, E, Wn, fin)``
    :math:`W_n = \Pi_V(W + h C)` (exact mirrors stay exact); ``fin[q]`` whether lane ``q`` is
    finite. With a compensation ``E`` (a buffer of the state's size; size 0: none) the sum is
    compensated, :math:`W_n + E' = W + (hC + E)` exactly up to the rounding of ``hC + E``
    (:func:`isoflow._compiled.flat.two_sum`), and ``E`` is overwritten by ``E'``.
``cayley_increment(lay, B, W, h, D)``
    :math:`D = C W C^\dagger - W` with the Cayley factor
    :math:`C = (I - \tfrac h2 B)^{-1}(I + \tfrac h2 B)` (the Cayley update of
    :class:`isoflow.IsoMP`): on small dense states by a written-out inverse
    (:mod:`isoflow._compiled.cayley_small`); per particle on :math:`(\mathbb{R}^3,\times)^N`,
    the rotation
    :math:`d_i = \tfrac{2}{1 + |u|^2}\,(u \times w_i + u \times (u \times w_i))`,
    :math:`u = \tfrac h2 b_i` (:func:`isoflow._compiled.particles.so3_cayley`).
``spherical_point(lay, W, M, mid)``
    The spherical midpoint's point ``m_i = sqrt(|w_i| |2 M_i - w_i|) M_i / |M_i|`` per
    particle (particle layouts on :math:`(\mathbb{R}^3, \times)` only).
``lane_sumsq(lay, W, out)``
    ``out[q] = |W_q|^2`` per lane (the scale of the stopping rule).
``select_lanes(lay, X, G, going)``
    ``X_q = G_q`` for the lanes still iterating.
``commit_lanes(lay, W, Wn, ok)``
    ``W_q = Wn_q`` for the lanes whose step succeeded.
``store(lay, out, row, m0, count, W)``
    Write the unit's members ``m0 .. m0 + count - 1`` into ``out[row]`` (``(R, M, S1)``).

Layouts with one member per unit get :func:`lanes`, :func:`lane_sumsq`, :func:`select_lanes`,
:func:`commit_lanes` and :func:`store` on the flat state from
:func:`provide_member_defaults`.

Registering an implementation: ``@provide(bracket_triple, DenseSmall)`` on a
``numba.njit(inline="always")`` function with the block's arguments. The blocks are resolved
at compile time; calling one from Python raises ``NotImplementedError``.

Inlined in numba's IR, a block is compiled with the flags of the stage it lands in, not with
its own: a ``fastmath`` on the block's decorator would do nothing. The stages have none, so a
block's arithmetic is neither reassociated nor contracted, and a loop compiled in a run's
process gives the same states as one loaded from numba's cache (reassociation made the two
differ once: :mod:`isoflow._compiled.dense_tiles`). A fused specialization that needs other
flags compiles a function of its own that the stage calls (the BLAS tiles, the spin chain's
sweeps), with the flags stated there.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any

import numba
from numba.core import errors as numba_errors
from numba.extending import overload

__all__ = [
    "BLOCKS",
    "advance_state",
    "bracket",
    "bracket_triple",
    "commit_lanes",
    "evaluate_B",
    "lane_sumsq",
    "lanes",
    "provide",
    "provide_generic_stage_map",
    "provide_member_defaults",
    "provided",
    "select_lanes",
    "spherical_point",
    "stage_map",
    "stage_update",
    "stage_update1",
    "store",
]

#: block function -> {layout record class: implementation}
_IMPLS: dict[Callable[..., Any], dict[type, Any]] = {}
#: (block, layout record class) -> the Python function numba compiles for the call
_FORWARDERS: dict[tuple[Callable[..., Any], type], Callable[..., Any]] = {}


def _forwarder(fn: Callable[..., Any], cls: type, impl: Any) -> Callable[..., Any]:
    """A plain function with the block's parameters that calls ``impl`` (what ``overload``
    wants: a Python function, not a compiled dispatcher)."""
    key = (fn, cls)
    fwd = _FORWARDERS.get(key)
    if fwd is None:
        params = ", ".join(inspect.signature(fn).parameters)
        namespace: dict[str, Any] = {"impl": impl}
        exec(f"def forward({params}):\n    return impl({params})\n", namespace)
        fwd = _FORWARDERS[key] = namespace["forward"]
    return fwd


def _block(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Declare ``fn`` (a stub with the block's signature and docstring) a block."""
    _IMPLS[fn] = {}

    def resolve(lay: Any) -> Callable[..., Any]:
        cls = getattr(lay, "instance_class", None)
        impl = _IMPLS[fn].get(cls) if cls is not None else None
        if cls is None or impl is None:
            raise numba_errors.TypingError(
                f"the layout {cls.__name__ if cls else lay} does not provide the block "
                f"{fn.__name__}"
            )
        return _forwarder(fn, cls, impl)

    # numba checks that the typing function has the block's parameters: write it with them
    params = ", ".join(inspect.signature(fn).parameters)
    namespace: dict[str, Any] = {"resolve": resolve}
    exec(f"def typer({params}):\n    return resolve(lay)\n", namespace)
    overload(fn)(namespace["typer"])
    return fn


def _stub(name: str) -> NotImplementedError:
    return NotImplementedError(f"{name} is a compiled block: call it from numba code")


@_block
def lanes(lay: Any) -> int:
    """Members per unit of the layout."""
    raise _stub("lanes")


@_block
def evaluate_B(lay: Any, f: Any, fargs: Any, X: Any, B: Any) -> None:
    """``B = B(X)`` on the unit's flat buffers."""
    raise _stub("evaluate_B")


@_block
def bracket_triple(lay: Any, B: Any, X: Any, C: Any, T: Any) -> None:
    """``C = [B, X]``, ``T = B X B``."""
    raise _stub("bracket_triple")


@_block
def bracket(lay: Any, B: Any, X: Any, C: Any) -> None:
    """``C = [B, X]``."""
    raise _stub("bracket")


@_block
def stage_update(lay: Any, W: Any, a: Any, C: Any, b: Any, T: Any, G: Any, X: Any, rr: Any) -> None:
    """``G = Pi(W + a C + b T)``, ``rr[q] = |G - X|^2``."""
    raise _stub("stage_update")


@_block
def stage_update1(lay: Any, W: Any, a: Any, C: Any, G: Any, X: Any, rr: Any) -> None:
    """``G = Pi(W + a C)``, ``rr[q] = |G - X|^2``."""
    raise _stub("stage_update1")


@_block
def stage_map(lay: Any, W: Any, h: Any, B: Any, X: Any, G: Any, C: Any, T: Any, rr: Any) -> None:
    """IsoMP's stage map for the field ``B``: ``G``, the finish's bracket ``C`` and
    ``rr[q] = |G - X|^2`` (``T`` scratch)."""
    raise _stub("stage_map")


@_block
def cayley_increment(lay: Any, B: Any, W: Any, h: Any, D: Any) -> None:
    """``D = C W C^H - W`` with the Cayley factor of ``h/2 B``."""
    raise _stub("cayley_increment")


@_block
def advance_state(lay: Any, W: Any, h: Any, C: Any, E: Any, Wn: Any, fin: Any) -> None:
    """``Wn = Pi_V(W + h C)`` (compensated by ``E`` unless it is empty); ``fin[q]`` whether
    lane ``q`` is finite."""
    raise _stub("advance_state")


@_block
def spherical_point(lay: Any, W: Any, M: Any, mid: Any) -> None:
    """The spherical midpoint's point of every particle."""
    raise _stub("spherical_point")


@_block
def lane_sumsq(lay: Any, W: Any, out: Any) -> None:
    """``out[q] = |W_q|^2``."""
    raise _stub("lane_sumsq")


@_block
def select_lanes(lay: Any, X: Any, G: Any, going: Any) -> None:
    """``X_q = G_q`` where ``going[q]``."""
    raise _stub("select_lanes")


@_block
def commit_lanes(lay: Any, W: Any, Wn: Any, ok: Any) -> None:
    """``W_q = Wn_q`` where ``ok[q]``."""
    raise _stub("commit_lanes")


@_block
def store(lay: Any, out: Any, row: Any, m0: Any, count: Any, W: Any) -> None:
    """The unit's members into ``out[row, m0 : m0 + count]``."""
    raise _stub("store")


#: Every block, by name.
BLOCKS: dict[str, Callable[..., Any]] = {fn.__name__: fn for fn in _IMPLS}


def provide(block: Callable[..., Any], *layouts: type) -> Callable[[Any], Any]:
    """Register the decorated compiled function as ``block`` for the layout record classes."""
    if block not in _IMPLS:
        raise ValueError(f"{block!r} is not a block")

    def register(impl: Any) -> Any:
        for cls in layouts:
            _IMPLS[block][cls] = impl
        return impl

    return register


def provided(layout: type) -> frozenset[str]:
    """Names of the blocks the layout record class provides."""
    return frozenset(fn.__name__ for fn, impls in _IMPLS.items() if layout in impls)


# ---- the defaults of layouts with one member per unit -----------------------------------------


@numba.njit(cache=True, inline="always")
def _one_lane(lay):  # type: ignore[no-untyped-def]
    return 1


@numba.njit(cache=True, inline="always")
def _member_sumsq(lay, W, out):  # type: ignore[no-untyped-def]
    acc = 0.0
    for i in range(W.shape[0]):
        v = W[i]
        acc += v.real * v.real + v.imag * v.imag
    out[0] = acc


@numba.njit(cache=True, inline="always")
def _member_select(lay, X, G, going):  # type: ignore[no-untyped-def]
    if going[0]:
        for i in range(X.shape[0]):
            X[i] = G[i]


@numba.njit(cache=True, inline="always")
def _member_commit(lay, W, Wn, ok):  # type: ignore[no-untyped-def]
    if ok[0]:
        for i in range(W.shape[0]):
            W[i] = Wn[i]


@numba.njit(cache=True, inline="always")
def _member_store(lay, out, row, m0, count, W):  # type: ignore[no-untyped-def]
    dst = out[row, m0]
    for i in range(W.shape[0]):
        dst[i] = W[i]


def provide_member_defaults(*layouts: type) -> None:
    """The lane blocks of layouts with one member per unit (the flat state is the member)."""
    for block, impl in (
        (lanes, _one_lane),
        (lane_sumsq, _member_sumsq),
        (select_lanes, _member_select),
        (commit_lanes, _member_commit),
        (store, _member_store),
    ):
        provide(block, *layouts)(impl)


@numba.njit(cache=True, inline="always")
def _generic_stage_map(lay, W, h, B, X, G, C, T, rr):  # type: ignore[no-untyped-def]
    """``C = [B, X]``, ``T = B X B``, ``G = Pi(W + h/2 C + h^2/4 T)``: the layout's own
    :func:`bracket_triple` and :func:`stage_update`."""
    bracket_triple(lay, B, X, C, T)
    stage_update(lay, W, 0.5 * h, C, 0.25 * h * h, T, G, X, rr)


def provide_generic_stage_map(*layouts: type) -> None:
    """:func:`stage_map` from the layouts' :func:`bracket_triple` and :func:`stage_update`."""
    provide(stage_map, *layouts)(_generic_stage_map)
