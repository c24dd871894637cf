"""Selection of a compiled fast path for :meth:`IsoMP.advance` / ``SphericalMidpoint.advance``.

A fast path is taken only when it computes the same thing as the NumPy path: the default
:class:`~isoflow.FixedPoint` solver (exactly that class), a problem kernel matching the space,
and the state in the space's dtype. Otherwise these functions return ``None`` and the method
falls back to its Python loop over ``step``.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ..algebras.hermitian import Hermitian
from ..algebras.orthogonal import SpecialOrthogonal
from ..algebras.sl2_vectors import SL2Vectors
from ..algebras.spin import SpinVectors
from ..algebras.symmetric import Symmetric
from ..algebras.unitary import SpecialUnitary, Unitary
from ..methods._base import AdvanceResult, StepResult
from ..nonlinear import FixedPoint
from ..problems import IsospectralProblem
from .kernels import ElementwiseLinear, PairwiseVortex, SpinNeighbourSum

if TYPE_CHECKING:
    from ..methods.isomp import IsoMP

__all__ = ["SMALL_N", "isomp_advance", "sigma_sign", "smm_advance"]

Array = NDArray[Any]

#: Largest ``n`` for which the written-out compiled products beat BLAS calls.
SMALL_N = 48
#: Smallest single-matrix ``n`` for the buffered BLAS path (below, the Python loop is as fast).
LARGE_N = 128
#: Smallest ensemble for which members are spread over numba threads.
PARALLEL_MIN_MEMBERS = 32
#: Smallest ensemble advanced in the blocked member-innermost layout.
BLOCKED_MIN_MEMBERS = 8
#: Smallest spin chain spread over numba threads.
PARALLEL_MIN_SPINS = 200_000


def sigma_sign(alg: Any) -> float | None:
    r"""``s`` with :math:`\sigma(Y) = s\,\bar Y^T` for the five spaces the fast paths know
    (``su(n)`` is ``u(n)`` plus the trace removal of its projection, see ``alg.traceless``)."""
    t = type(alg)
    if t is SpecialOrthogonal or t is Unitary or t is SpecialUnitary:
        return -1.0
    if t is Symmetric or t is Hermitian:
        return 1.0
    return None


def _extrap_table(K: int) -> Array:
    from ..methods.isomp import extrapolation_weights

    tab = np.zeros((K, K))
    for m in range(1, K + 1):
        tab[m - 1, :m] = extrapolation_weights(m)
    return tab


def _threads() -> int:
    import numba

    return int(numba.get_num_threads())


def _result(
    out: dict[str, Any], Wf: Array, batch: tuple[int, ...], core: tuple[int, ...], h: float,
    keep_state: bool, n_hist_keep: int,
) -> tuple[Array, Any, StepResult | None]:  # fmt: skip
    """Reshape a kernel's output into ``(y, state, failure)``."""
    y = Wf.reshape(*batch, *core)
    hist = [D.reshape(*batch, *core).copy() for D in out["hist"]][::-1]  # newest first
    state = (h, *hist[:n_hist_keep]) if keep_state else None
    failure = None
    if out["n_done_requested"] != out["n_done"]:
        failure = StepResult(
            y=out["y_failed"].reshape(*batch, *core).copy(),
            stage=out["stage"].reshape(*batch, *core).copy(),
            iterations=out["iterations"].reshape(batch).copy(),
            residual=out["residual"].reshape(batch).copy(),
            status=out["status"].reshape(batch).copy(),
            state=None,
        )
    return y, state, failure


def isomp_advance(
    method: IsoMP, problem: IsospectralProblem, y: Array, h: float, n: int, state: Any
) -> AdvanceResult | None:
    """Compiled ``n`` steps of IsoMP, or ``None`` when no fast path applies."""
    return _isomp_advance(method, problem, problem.kernel, y, h, n, state)


def _isomp_advance(
    method: IsoMP, problem: IsospectralProblem, kernel: Any, y: Array, h: float, n: int,
    state: Any,
) -> AdvanceResult | None:  # fmt: skip
    """:func:`isomp_advance` with the kernel given (the frame-free one inside a frame)."""
    solver = method.solver
    if type(solver) is not FixedPoint or n < 1:
        return None
    alg = problem.algebra
    y = np.asarray(y)
    if y.dtype != alg.dtype:
        return None
    batch = alg.batch_shape(y)
    offsets = method.history(h, state)
    extrap = method.initial_guess == "extrapolate"
    K = method.extrapolation_order + 1 if extrap else 1
    if isinstance(kernel, ElementwiseLinear):
        s = sigma_sign(alg)
        if s is None or kernel.coeff.shape != alg.shape:
            return None
        if kernel.frame is not None:
            return _in_frame(method, problem, kernel, y, h, n, state)
        if alg.shape[0] > SMALL_N:
            if batch != ():
                return None
            from . import blas

            return blas.isomp_advance_large(method, problem, kernel.coeff, y, h, n, state)
        coeff = kernel.coeff
        return _dense_elementwise(method, coeff, alg, y, h, n, offsets, K, extrap, s, state)
    if isinstance(kernel, SpinNeighbourSum) and isinstance(alg, SpinVectors):
        return spin_advance("isomp", method, kernel, y, h, n, offsets, K, extrap, state)
    if isinstance(kernel, PairwiseVortex) and _vortex_fits(kernel, alg, y, "isomp"):
        return vortex_advance("isomp", method, kernel, y, h, n, offsets, K, extrap, state)
    if kernel is None and batch == () and sigma_sign(alg) is not None:
        if alg.shape[0] >= LARGE_N:
            from . import blas

            return blas.isomp_advance_large(method, problem, None, y, h, n, state)
    return None


def _in_frame(
    method: IsoMP, problem: IsospectralProblem, kernel: ElementwiseLinear, y: Array, h: float,
    n: int, state: Any,
) -> AdvanceResult | None:  # fmt: skip
    r"""IsoMP for ``B(W) = U (C * (U^H W U)) U^H``: the entrywise fast path on
    :math:`U^\dagger W U` (states and stored stage offsets), results mapped back by
    :math:`Y \mapsto \Pi(U Y U^\dagger)` (``Pi`` the projection onto the space, which only
    removes rounding). IsoMP is equivariant under this change of frame (see
    :class:`~isoflow._fast.kernels.ElementwiseLinear`).
    """
    alg = problem.algebra
    U = kernel.frame
    assert U is not None
    if np.result_type(U.dtype, alg.dtype) != alg.dtype:
        return None
    Uh = np.ascontiguousarray(U.conj().T)
    stage = alg.stage_algebra

    def into(A: Array) -> Array:
        return np.ascontiguousarray(Uh @ np.asarray(A) @ U)

    def back(A: Array, space: Any) -> Array:
        return np.asarray(space.project(U @ A @ Uh))

    rotated = state
    if state is not None and len(state) > 1:
        rotated = (state[0], *(into(D) for D in state[1:]))
    res = _isomp_advance(method, problem, ElementwiseLinear(kernel.coeff), into(y), h, n, rotated)
    if res is None:
        return None
    new_state = res.state
    if res.state is rotated:  # no step taken: the caller's state, untouched
        new_state = state
    elif res.state is not None:
        new_state = (res.state[0], *(back(D, stage) for D in res.state[1:]))
    failure = res.failure
    if failure is not None:
        fstage = None if failure.stage is None else back(failure.stage, stage)
        failure = dataclasses.replace(failure, y=back(failure.y, alg), stage=fstage)
    return dataclasses.replace(res, y=back(res.y, alg), state=new_state, failure=failure)


def smm_advance(
    method: Any, problem: IsospectralProblem, y: Array, h: float, n: int, state: Any
) -> AdvanceResult | None:
    """Compiled ``n`` steps of the spherical midpoint, or ``None`` when no fast path applies.

    ``method`` has ``solver``, ``initial_guess`` (``"extrapolate"`` reuses the previous
    offset ``M - w``, ``"state"`` starts at ``w``) like :class:`~isoflow.SphericalMidpoint`.
    """
    kernel = problem.kernel
    if type(method.solver) is not FixedPoint or n < 1:
        return None
    y = np.asarray(y)
    vortex = isinstance(kernel, PairwiseVortex) and _vortex_fits(kernel, problem.algebra, y, "smm")
    if not vortex and not (
        isinstance(kernel, SpinNeighbourSum) and isinstance(problem.algebra, SpinVectors)
    ):
        return None
    if y.dtype != np.float64:
        return None
    extrap = method.initial_guess == "extrapolate"
    offsets: tuple[Array, ...] = ()
    if extrap and state is not None and len(state) >= 2 and state[0] == h:
        offsets = (state[1],)
    if isinstance(kernel, PairwiseVortex):
        return vortex_advance("smm", method, kernel, y, h, n, offsets, 1, extrap, state)
    assert isinstance(kernel, SpinNeighbourSum)
    return spin_advance("smm", method, kernel, y, h, n, offsets, 1, extrap, state)


def _dense_elementwise(
    method: IsoMP, coeff: Array, alg: Any, y: Array, h: float, n: int,
    offsets: tuple[Array, ...], K: int, extrap: bool, s: float, state: Any,
) -> AdvanceResult:  # fmt: skip
    from .dense import advance_elementwise, advance_elementwise_blocked

    solver = method.solver
    core = alg.shape
    batch = alg.batch_shape(y)
    M = int(np.prod(batch)) if batch else 1
    Wf = np.array(y, dtype=alg.dtype, order="C", copy=True).reshape(M, *core)
    hist = np.zeros((K, M, *core), dtype=alg.dtype)
    nh = len(offsets) if extrap else 0
    for q, D in enumerate(offsets[::-1]):  # oldest .. newest
        hist[q] = np.asarray(D, dtype=alg.dtype).reshape(M, *core)
    coeff = np.ascontiguousarray(coeff)
    coefs = _extrap_table(K)
    blocked = M >= BLOCKED_MIN_MEMBERS
    run = advance_elementwise_blocked if blocked else advance_elementwise
    out = run(
        Wf, hist, nh, coefs, coeff, s, h, n, solver.rtol, solver.atol, solver.stall_rtol,
        solver.divergence_factor, solver.max_iter,
        parallel=M >= PARALLEL_MIN_MEMBERS and _threads() > 1,
        extrapolate=extrap,
        traceless=bool(alg.traceless),
    )  # fmt: skip
    if blocked:
        Wf = out["y"]
    out["n_done_requested"] = n
    y_out, new_state, failure = _result(out, Wf, batch, core, h, extrap, K)
    return AdvanceResult(
        y=y_out,
        state=new_state if out["n_done"] > 0 else state,
        n_done=out["n_done"],
        iterations_total=out["iterations_total"],
        iterations_max=out["iterations_max"],
        residual_max=out["residual_max"],
        failure=failure,
    )


def _particle_result(
    out: dict[str, Any], n: int, h: float, state: Any, extrap: bool, batch: tuple[int, ...],
    back: Any, offset_back: Any,
) -> AdvanceResult:  # fmt: skip
    """The :class:`AdvanceResult` of a compiled particle loop (:mod:`isoflow._fast.spin`,
    :mod:`isoflow._fast.vortices`): ``back`` maps a state of the loop's layout to the user's
    ``(*batch, N, 3)``, ``offset_back`` a stored stage offset; the caller's ``state`` is kept
    when no step was accepted."""
    failure = None
    if out["n_done"] != n:
        failure = StepResult(
            y=back(out["y_failed"]),
            stage=back(out["stage"]),
            iterations=out["iterations"].reshape(batch).copy(),
            residual=out["residual"].reshape(batch).copy(),
            status=out["status"].reshape(batch).copy(),
            state=None,
        )
    new_state = state
    if out["n_done"] > 0:
        new_state = (h, *[offset_back(D) for D in out["hist"][::-1]]) if extrap else None
    return AdvanceResult(
        y=back(out["y"]),
        state=new_state,
        n_done=out["n_done"],
        iterations_total=out["iterations_total"],
        iterations_max=out["iterations_max"],
        residual_max=out["residual_max"],
        failure=failure,
    )


def spin_advance(
    kind: str, method: Any, kernel: SpinNeighbourSum, y: Array, h: float, n: int,
    offsets: tuple[Array, ...], K: int, extrap: bool, state: Any,
) -> AdvanceResult:  # fmt: skip
    """Compiled ``n`` steps of IsoMP (``kind="isomp"``) or the spherical midpoint (``"smm"``)."""
    from .spin import advance_spin, to_aos, to_soa

    solver = method.solver
    N = y.shape[-2]
    batch = y.shape[:-2]
    M = int(np.prod(batch)) if batch else 1
    par = N >= PARALLEL_MIN_SPINS and _threads() > 1
    W = to_soa(y.reshape(M, N, 3))  # a new array: the input is never written
    hist = np.empty((K + 1, M, 3, N))  # slots are written before they are read
    nh = len(offsets) if extrap else 0
    for q, D in enumerate(offsets[::-1]):
        Dm = np.asarray(D, dtype=np.float64).reshape(M, N, 3)
        base = np.swapaxes(Dm, -1, -2)
        if base.flags.c_contiguous:  # an offset this function returned: a plain copy
            hist[q] = base
        else:
            to_soa(Dm, out=hist[q])
    coefs = _extrap_table(K)
    out = advance_spin(
        kind, W, hist, nh, extrap, coefs, kernel.coupling, h, n, solver.rtol, solver.atol,
        solver.stall_rtol, solver.divergence_factor, solver.max_iter, par,
    )  # fmt: skip

    def back(A: Array) -> Array:
        return to_aos(A).reshape(*batch, N, 3)

    def offset_view(A: Array) -> Array:
        # the stored offsets stay in this call's (3, N) buffers (never written again): an
        # (N, 3) view, no copy; the next call reads them back with a plain copy
        return np.swapaxes(A, -1, -2).reshape(*batch, N, 3)

    return _particle_result(out, n, h, state, extrap, batch, back, offset_view)


# ---- point vortices -----------------------------------------------------------------------------
#: Smallest vortex ensemble whose members are spread over numba threads (one system is
#: serial: ``N`` is small).
PARALLEL_MIN_VORTEX_MEMBERS = 2
#: ... and the smallest ``members * (N^2 + 50)`` (about the work of one iteration, the pairs
#: plus a per-member overhead) for that. Measured on 2 cores: a step of 16 members of 3
#: vortices (2.5 us) is slower threaded, 4 members of 100 vortices almost twice as fast.
PARALLEL_MIN_VORTEX_WORK = 4000


def _vortex_fits(kernel: PairwiseVortex, alg: Any, y: Array, kind: str) -> bool:
    """Whether ``kernel`` runs compiled on ``alg`` for ``y``: the sphere on
    :class:`SpinVectors`, the hyperboloid on :class:`SL2Vectors` (IsoMP only), ``N`` vortices
    and a ``float64`` state ``(*batch, N, 3)``."""
    space = SpinVectors if kernel.geometry == "sphere" else SL2Vectors
    if kind == "smm" and kernel.geometry != "sphere":
        return False
    return (
        type(alg) is space
        and alg.N == kernel.N
        and y.dtype == np.float64
        and y.ndim >= 2
        and y.shape[-2:] == (kernel.N, 3)
    )


def vortex_advance(
    kind: str, method: Any, kernel: PairwiseVortex, y: Array, h: float, n: int,
    offsets: tuple[Array, ...], K: int, extrap: bool, state: Any,
) -> AdvanceResult:  # fmt: skip
    """Compiled ``n`` steps of IsoMP (``kind="isomp"``) or the spherical midpoint (``"smm"``)
    for the point-vortex field :class:`~isoflow._fast.kernels.PairwiseVortex`.

    Same conventions as :func:`spin_advance`: ``offsets`` are the stored stage offsets, newest
    first, ``K`` the ring length (offsets kept), ``extrap`` whether the method extrapolates;
    on failure ``y`` is the last good state and ``failure`` the rejected step.
    """
    from .vortices import advance_vortices

    solver = method.solver
    N = y.shape[-2]
    batch = y.shape[:-2]
    M = int(np.prod(batch)) if batch else 1
    par = (
        M >= PARALLEL_MIN_VORTEX_MEMBERS
        and M * (N * N + 50) >= PARALLEL_MIN_VORTEX_WORK
        and _threads() > 1
    )
    nh = len(offsets) if extrap else 0
    hist = [np.asarray(D, dtype=np.float64).reshape(M, N, 3) for D in offsets[:nh][::-1]]
    out = advance_vortices(
        kind, kernel.geometry, y.reshape(M, N, 3), hist, K, extrap, _extrap_table(K),
        kernel.circulations, kernel.coefficient, h, n, solver.rtol, solver.atol,
        solver.stall_rtol, solver.divergence_factor, solver.max_iter, par,
    )  # fmt: skip

    def back(A: Array) -> Array:
        return A.reshape(*batch, N, 3)

    return _particle_result(out, n, h, state, extrap, batch, back, back)
