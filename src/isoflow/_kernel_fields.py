r"""The compiled field functions ``f(W, out, *args)`` of the built-in kernels, and calling any.

Each field evaluates ``B`` for one system (see :mod:`isoflow.kernels` for the protocol).
Imported on first use: importing :mod:`isoflow` does not load numba.

Fields are passed to compiled code as *first-class function values* of an explicit type
(:func:`field_type`: ``void(W, out, *args)`` with C-contiguous 2-d arrays), not as numba
dispatcher objects: a compiled function that takes a dispatcher argument is specialized on
that object's identity, which numba's on-disk cache cannot key across processes (every new
process would compile again and grow the cache). With the function type, a compiled loop is
specialized only on the argument *types*, so it is compiled once per machine and shared by
every field of the same signature.
"""

from __future__ import annotations

from typing import Any

import numba
import numpy as np
from numba import types

from ._errors import InvalidBError

__all__ = [
    "apply_field",
    "elementwise",
    "elementwise_in_frame",
    "field_type",
    "heavy_top",
    "neighbour_sum",
    "vortex_hyperbolic",
    "vortex_sphere",
]


def field_type(f: Any, args: tuple[Any, ...], dtype: Any, out_dtype: Any, ndim: int = 2) -> Any:
    """The function type ``void(W, out, *args)`` of a field, with ``f`` compiled for it.

    ``W`` and ``out`` are C-contiguous arrays of ``dtype`` and ``out_dtype`` with ``ndim``
    axes, those of one state (2 for matrices and particle arrays, 3 for the pairs of matrices
    of :func:`isoflow.algebras.semidirect`).

    Raises
    ------
    InvalidBError
        ``f`` does not compile for these argument types (wrong number of arguments, writes a
        complex value into a real ``out``, ...), with numba's first message.
    """
    W_t = types.Array(numba.from_dtype(np.dtype(dtype)), ndim, "C")
    out_t = types.Array(numba.from_dtype(np.dtype(out_dtype)), ndim, "C")
    args_t = numba.typeof(args)
    sig = types.void(W_t, out_t, *args_t.types)
    if sig.args in f.overloads:  # compiled earlier: skip numba's compiler lock
        return types.FunctionType(sig)
    name = getattr(f, "__name__", "f")
    try:
        f.compile(sig)
    except Exception as exc:
        first = _numba_reason(exc)
        raise InvalidBError(
            f"the kernel function {name} does not compile for f(W, out, *args) with W: "
            f"{W_t}, out: {out_t}, args: {args_t}: {first}"
        ) from exc
    if f.overloads[sig.args].objectmode:  # compiled code cannot call it: it has no C entry
        raise InvalidBError(
            f"the kernel function {name} compiled in object mode; compiled loops call only "
            "nopython functions: decorate it with @numba.njit(cache=True)"
        )
    return types.FunctionType(sig)


def _numba_reason(exc: BaseException) -> str:
    """The line of a numba compile error that says what is wrong: numba's first line names
    only the compiler stage ("Failed in nopython mode pipeline ..."), the reason follows; an
    explicit signature that does not match says "compilation disabled"."""
    text = str(exc).strip()
    if not text:
        return type(exc).__name__
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    useful = [
        ln for ln in lines
        if not ln.startswith(("Failed in ", "During: ", "File ", "^", "<source", "- Resolution"))
    ]  # fmt: skip
    reason = useful[0] if useful else lines[0]
    if reason.endswith(":") and len(useful) > 1:  # "... found for signature:" and the signature
        reason += " " + useful[1].lstrip("> ")
    if "compilation disabled" in text:
        reason += (
            " (f was compiled for an explicit signature; compiled loops call it with "
            "C-contiguous arrays, e.g. float64[:, ::1]: drop the signature or declare those)"
        )
    return " ".join(reason.split())[:400]


def _apply(f, args, W, out):  # type: ignore[no-untyped-def]
    for m in range(W.shape[0]):
        f(W[m], out[m], *args)


_APPLY: dict[Any, Any] = {}


def apply_field(f: Any, args: tuple[Any, ...], W: Any, out: Any) -> None:
    """``f(W[m], out[m], *args)`` for every member ``m`` of the stacked ``(M, ...)`` states."""
    f_t = field_type(f, args, W.dtype, out.dtype, W.ndim - 1)
    args_t = numba.typeof(args)
    sig = types.none(
        f_t,
        args_t,
        types.Array(numba.from_dtype(W.dtype), W.ndim, "C"),
        types.Array(numba.from_dtype(out.dtype), W.ndim, "C"),
    )
    run = _APPLY.get(sig)
    if run is None:
        from ._compile_clock import compile_notice

        name = getattr(f, "__name__", "f")
        with compile_notice(f"the wrapper that calls {name} from Python"):
            run = _APPLY[sig] = numba.njit(sig, cache=True)(_apply)
    run(f, args, np.ascontiguousarray(W), out)


@numba.njit(cache=True)
def elementwise(W, out, C):  # type: ignore[no-untyped-def]
    r"""``out = C \circ W``."""
    n = W.shape[0]
    for i in range(n):
        for j in range(W.shape[1]):
            out[i, j] = C[i, j] * W[i, j]


@numba.njit(cache=True)
def elementwise_in_frame(W, out, C, U, Uh):  # type: ignore[no-untyped-def]
    r"""``out = U (C \circ (U^\dagger W U)) U^\dagger`` (the frame in ``W``'s dtype)."""
    Ut = U.astype(W.dtype)
    Uht = Uh.astype(W.dtype)
    A = np.dot(np.dot(Uht, W), Ut) * C
    out[:, :] = np.dot(np.dot(Ut, A), Uht)


@numba.njit(cache=True)
def neighbour_sum(W, out, c):  # type: ignore[no-untyped-def]
    r"""``out_i = c (w_{i-1} + w_{i+1})``, periodic, on ``(N, 3)``."""
    N = W.shape[0]
    for i in range(N):
        im = i - 1 if i > 0 else N - 1
        ip = i + 1 if i < N - 1 else 0
        for a in range(3):
            out[i, a] = c * (W[im, a] + W[ip, a])


@numba.njit(cache=True)
def neighbour_sum_gilbert(W, out, c, lam):  # type: ignore[no-untyped-def]
    r"""``out_i = h_i + lam w_i x h_i`` with ``h_i = c (w_{i-1} + w_{i+1})``, periodic, on
    ``(N, 3)``: the neighbour sum with Gilbert damping (the chain's fused sweeps,
    :mod:`isoflow._compiled.spin_chain`, form the same terms in the same order)."""
    N = W.shape[0]
    for i in range(N):
        im = i - 1 if i > 0 else N - 1
        ip = i + 1 if i < N - 1 else 0
        h0 = c * (W[im, 0] + W[ip, 0])
        h1 = c * (W[im, 1] + W[ip, 1])
        h2 = c * (W[im, 2] + W[ip, 2])
        s0, s1, s2 = W[i, 0], W[i, 1], W[i, 2]
        out[i, 0] = h0 + lam * (s1 * h2 - s2 * h1)
        out[i, 1] = h1 + lam * (s2 * h0 - s0 * h2)
        out[i, 2] = h2 + lam * (s0 * h1 - s1 * h0)


@numba.njit(cache=True, inline="always", error_model="numpy")
def pair_field(X, B, circ, c, N, lorentz):  # type: ignore[no-untyped-def]
    r"""The pair sum :math:`B_i = c \sum_{j \ne i} \Gamma_j\, q(D_{ij})\, x_j` on flat
    ``(3N,)`` arrays: :math:`q(D) = 1/(1 - D)` with the Euclidean dot, or (``lorentz``)
    :math:`q(D) = 1/((D - 1)(D + 1))` with :math:`D = x_i \cdot_L x_j`.

    One pass over the pairs ``i < j`` (the factor is symmetric); each ``B_i`` sums its terms
    in the order ``j = 0, 1, ..., N-1``. A coinciding pair gives ``inf`` (then ``non_finite``).
    The one statement of the vortex fields: the kernel's fields below and the fused compiled
    stages (:mod:`isoflow._compiled.vortices`) use it.
    """
    for k in range(3 * N):
        B[k] = 0.0
    for i in range(N):
        p = 3 * i
        xi0, xi1, xi2 = X[p], X[p + 1], X[p + 2]
        gi = circ[i]
        s0, s1, s2 = B[p], B[p + 1], B[p + 2]
        for j in range(i + 1, N):
            r = 3 * j
            xj0, xj1, xj2 = X[r], X[r + 1], X[r + 2]
            if lorentz:
                d = xi0 * xj0 + xi1 * xj1 - xi2 * xj2
                q = 1.0 / ((d - 1.0) * (d + 1.0))
            else:
                q = 1.0 / (1.0 - (xi0 * xj0 + xi1 * xj1 + xi2 * xj2))
            a = circ[j] * q
            s0 += a * xj0
            s1 += a * xj1
            s2 += a * xj2
            a = gi * q
            B[r] += a * xi0
            B[r + 1] += a * xi1
            B[r + 2] += a * xi2
        B[p] = c * s0
        B[p + 1] = c * s1
        B[p + 2] = c * s2


@numba.njit(cache=True, error_model="numpy")
def vortex_sphere(W, out, circ, c):  # type: ignore[no-untyped-def]
    r"""``out_i = c \sum_{j \ne i} \Gamma_j w_j / (1 - w_i \cdot w_j)`` on ``(N, 3)``."""
    N = W.shape[0]
    flat = np.empty(3 * N)  # any layouts of W and out: the pair sum runs on flat copies
    pair_field(np.ascontiguousarray(W).ravel(), flat, circ, c, N, False)
    out[:, :] = flat.reshape(N, 3)


@numba.njit(cache=True, error_model="numpy")
def vortex_hyperbolic(W, out, circ, c):  # type: ignore[no-untyped-def]
    r"""``out_i = c \sum_{j \ne i} \Gamma_j w_j / ((D_{ij} - 1)(D_{ij} + 1))``,
    :math:`D_{ij} = w_i \cdot_L w_j`, on ``(N, 3)``."""
    N = W.shape[0]
    flat = np.empty(3 * N)  # any layouts of W and out: the pair sum runs on flat copies
    pair_field(np.ascontiguousarray(W).ravel(), flat, circ, c, N, True)
    out[:, :] = flat.reshape(N, 3)


@numba.njit(cache=True)
def heavy_top(W, out, inv_inertia, gravity):  # type: ignore[no-untyped-def]
    r"""The heavy top's ``B = -(I^{-1} M, gravity)`` on the pair ``W = (Gamma, M)`` (``(2, 3)``):
    ``gravity`` is :math:`\partial H/\partial\Gamma = m g l\,\chi`
    (:func:`isoflow.models.heavy_top`)."""
    for a in range(3):
        out[0, a] = -inv_inertia[a] * W[1, a]
        out[1, a] = -gravity[a]
