r"""Nonlinear solvers for the implicit stage of a method: find ``X`` with ``X = G(X)``.

Both solvers work per ensemble member: a member that has converged is frozen (its ``X`` is no
longer updated and ``G`` is no longer evaluated on it), so an ensemble gives the same answer as
separate runs.

Stopping rules (per member, ``r_k = ||G(X_k) - X_k||`` in the norm of the space, ``s`` the
scale passed in, usually ``||W_k||``):

1. **converged** when ``r_k <= atol + rtol * s``;
2. **converged at the rounding floor** when the residual stops decreasing
   (``r_k >= r_{k-1}``) while already small, ``r_k <= stall_rtol * s``: the iteration cannot get
   any closer in floating point;
3. **non-finite**: ``r_k`` is NaN or Inf (``B`` returned NaN/Inf, or the iteration overflowed);
4. **diverged**: ``r_k > divergence_factor * r_0`` and ``r_k > atol + rtol * s``;
5. **max_iter**: ``max_iter`` evaluations of ``G`` without meeting rules 1-2.

Rules 3-5 are failures; the caller decides whether to raise
:class:`~isoflow.ConvergenceError` or to report it. The accepted ``X`` is the last point at which
``G`` was evaluated, so the auxiliary output of ``G`` (e.g. the bracket ``[B(X), X]``) belongs to
exactly that ``X``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import scipy.sparse.linalg as spla
from numpy.typing import NDArray

from .algebras import Algebra

__all__ = [
    "STATUS_CONVERGED",
    "STATUS_DIVERGED",
    "STATUS_MAX_ITER",
    "STATUS_NON_FINITE",
    "FixedPoint",
    "FixedPointProblem",
    "Newton",
    "NonlinearResult",
    "NonlinearSolver",
]

Array = NDArray[Any]

STATUS_CONVERGED = 0
STATUS_MAX_ITER = 1
STATUS_DIVERGED = 2
STATUS_NON_FINITE = 3
STATUS_NAMES = {
    STATUS_CONVERGED: "converged",
    STATUS_MAX_ITER: "max_iter",
    STATUS_DIVERGED: "diverged",
    STATUS_NON_FINITE: "non_finite",
}

#: Returned by :func:`stopping_step` while the iteration goes on.
STATUS_RUNNING = -1


def stopping_step(
    r: float, prev: float, first: float, it: int, tol: float, floor: float, divergence: float
) -> tuple[int, float, float]:
    """The stopping rules of the module for one member at iteration ``it`` (1-based).

    ``r`` is the current residual, ``prev`` the previous one (``inf`` at the first
    iteration), ``first`` the first one (``inf`` before it), ``tol = atol + rtol s`` and
    ``floor = stall_rtol s``. Returns ``(code, prev, first)``: a ``STATUS_*`` code
    (``STATUS_RUNNING`` to go on) and the ``prev`` and ``first`` to pass at the next
    iteration. This one function is the rule everywhere: the Python solvers call it, the
    compiled kernels of :mod:`isoflow._fast` use a numba compilation of it.
    """
    if not math.isfinite(r):
        code = STATUS_NON_FINITE
    elif r <= tol or (r >= prev and r <= floor):
        code = STATUS_CONVERGED
    elif it > 1 and r > divergence * first:
        code = STATUS_DIVERGED
    else:
        code = STATUS_RUNNING
    return code, r, (r if it == 1 else first)


#: ``G(X, mask) -> (G(X), aux)``. ``mask`` is ``None`` when ``X`` is the whole ensemble
#: (original batch shape) and a boolean array over the batch axes when ``X`` holds only the
#: selected members, stacked on one leading axis.
FixedPointMap = Callable[[Array, "Array | None"], tuple[Array, Array]]
#: ``DG(X)[dX]``, same ``mask`` convention.
FixedPointJvp = Callable[[Array, Array, "Array | None"], Array]


@dataclass(frozen=True)
class FixedPointProblem:
    """What a method hands to a nonlinear solver.

    Attributes
    ----------
    G : callable
        The fixed-point map and its auxiliary output, see :data:`FixedPointMap`.
    algebra : Algebra
        Space of the unknown (norms, coordinates for Newton).
    scale : ndarray
        Per-member scale for the relative tolerance, shape = batch shape.
    jvp : callable or None
        Directional derivative of ``G``; Newton falls back to finite differences without it.
    """

    G: FixedPointMap
    algebra: Algebra
    scale: Array
    jvp: FixedPointJvp | None = None


@dataclass(frozen=True)
class NonlinearResult:
    """Outcome of one nonlinear solve, per ensemble member.

    Attributes
    ----------
    x : ndarray
        Accepted iterate, shape ``(*batch, *shape)``.
    aux : ndarray
        Auxiliary output of ``G`` at ``x``.
    iterations : ndarray of int
        Evaluations of ``G`` per member.
    residual : ndarray of float
        ``||G(x) - x||`` per member.
    status : ndarray of int
        ``STATUS_CONVERGED`` (0) or a failure code, per member.
    """

    x: Array
    aux: Array
    iterations: NDArray[np.int64]
    residual: NDArray[np.float64]
    status: NDArray[np.int64]

    @property
    def converged(self) -> NDArray[np.bool_]:
        """Per-member success."""
        return self.status == STATUS_CONVERGED

    @property
    def success(self) -> bool:
        """Whether every member converged."""
        return bool(np.all(self.status == STATUS_CONVERGED))


@dataclass(frozen=True)
class _StoppingRules:
    rtol: float
    atol: float
    max_iter: int
    stall_rtol: float
    divergence_factor: float

    def check(self) -> None:
        if not (self.rtol >= 0 and self.atol >= 0 and self.rtol + self.atol > 0):
            raise ValueError("tolerances must be non-negative and not both zero")
        if self.max_iter < 1:
            raise ValueError(f"max_iter must be >= 1, got {self.max_iter}")


class NonlinearSolver:
    """Common driver: iterate ``update`` per member under the stopping rules of the module."""

    rtol: float
    atol: float
    max_iter: int
    stall_rtol: float
    divergence_factor: float

    def _update(
        self, prob: FixedPointProblem, X: Array, GX: Array, mask: Array | None
    ) -> Array:  # pragma: no cover - abstract
        raise NotImplementedError

    def solve(self, prob: FixedPointProblem, X0: Array) -> NonlinearResult:
        """Solve ``X = G(X)`` starting from ``X0`` (not modified)."""
        alg = prob.algebra
        batch = alg.batch_shape(X0)
        if batch == ():
            return self._solve_single(prob, X0)
        X = np.array(X0, dtype=alg.dtype, copy=True)
        aux: Array | None = None
        iters = np.zeros(batch, dtype=np.int64)
        resid = np.full(batch, np.inf)
        status = np.full(batch, -1, dtype=np.int64)  # -1: still running
        first = np.full(batch, np.nan)
        tol = self.atol + self.rtol * prob.scale
        floor = self.stall_rtol * prob.scale
        active = np.ones(batch, dtype=bool)
        for _ in range(self.max_iter):
            whole = bool(active.all())
            mask = None if whole else active
            Xa = X if whole else X[active]
            GX, aux_a = prob.G(Xa, mask)
            r = alg.norm(GX - Xa)
            if aux is None:
                aux = np.zeros((*batch, *aux_a.shape[len(r.shape) :]), dtype=aux_a.dtype)
            sel = (...,) if whole else active
            prev = np.array(resid[sel], copy=True)
            r0 = np.where(np.isnan(first[sel]), r, first[sel])
            first[sel] = r0
            tol_a, floor_a = tol[sel], floor[sel]
            iters[sel] += 1
            resid[sel] = r
            aux[sel] = aux_a
            done_ok = (r <= tol_a) | ((r >= prev) & (r <= floor_a))
            non_finite = ~np.isfinite(r)
            diverged = (r > self.divergence_factor * r0) & (r > tol_a) & ~non_finite
            st = np.full(r.shape, -1, dtype=np.int64)
            st[done_ok] = STATUS_CONVERGED
            st[diverged] = STATUS_DIVERGED
            st[non_finite] = STATUS_NON_FINITE
            status[sel] = st
            going = st < 0
            if np.any(going):
                Xnew = self._update(prob, Xa, GX, mask)
                if whole:
                    X = np.where(_expand(going, alg), Xnew, X) if not going.all() else Xnew
                else:
                    Xa = np.where(_expand(going, alg), Xnew, Xa)
                    X[active] = Xa
            active = status < 0
            if not active.any():
                break
        status[status < 0] = STATUS_MAX_ITER
        assert aux is not None
        return NonlinearResult(x=X, aux=aux, iterations=iters, residual=resid, status=status)

    def _solve_single(self, prob: FixedPointProblem, X0: Array) -> NonlinearResult:
        """The same rules for one system, with Python scalars (no per-member bookkeeping)."""
        X = np.asarray(X0, dtype=prob.algebra.dtype)
        scale = float(prob.scale)
        tol = self.atol + self.rtol * scale
        floor = self.stall_rtol * scale
        prev = first = math.inf
        status = STATUS_MAX_ITER
        it = 0
        r = math.inf
        aux: Array | None = None
        for it in range(1, self.max_iter + 1):
            GX, aux = prob.G(X, None)
            r = float(np.linalg.norm((GX - X).ravel()))
            code, prev, first = stopping_step(
                r, prev, first, it, tol, floor, self.divergence_factor
            )
            if code != STATUS_RUNNING:
                status = code
                break
            X = self._update(prob, X, GX, None)
        assert aux is not None
        return NonlinearResult(
            x=X,
            aux=aux,
            iterations=np.asarray(it, dtype=np.int64),
            residual=np.asarray(r),
            status=np.asarray(status, dtype=np.int64),
        )


def _expand(mask: Array, alg: Algebra) -> Array:
    return mask.reshape(mask.shape + (1,) * alg.core_ndim)


@dataclass(frozen=True)
class FixedPoint(NonlinearSolver):
    """Plain fixed-point iteration ``X <- G(X)`` (the default).

    For IsoMP one iteration costs one evaluation of ``B`` and two matrix products. It converges
    when ``h ||B||`` is small enough (contraction); see the module docstring for the rules.

    Parameters
    ----------
    rtol, atol : float
        Residual tolerance ``atol + rtol * ||W_k||``.
    max_iter : int
        Largest number of iterations per step.
    stall_rtol : float
        A residual that stops decreasing below ``stall_rtol * ||W_k||`` is accepted.
    divergence_factor : float
        Growth of the residual over its first value that counts as divergence.
    """

    rtol: float = 1e-14
    atol: float = 0.0
    max_iter: int = 200
    stall_rtol: float = 1e-12
    divergence_factor: float = 1e4

    def __post_init__(self) -> None:
        _StoppingRules(
            self.rtol, self.atol, self.max_iter, self.stall_rtol, self.divergence_factor
        ).check()

    def _update(self, prob: FixedPointProblem, X: Array, GX: Array, mask: Array | None) -> Array:
        return GX


@dataclass(frozen=True)
class Newton(NonlinearSolver):
    r"""Newton's method on ``F(X) = X - G(X)`` in coordinates of the stage space.

    Parameters
    ----------
    jacobian : {"dense", "krylov"}
        ``"dense"`` assembles ``I - DG(X)`` in an orthonormal basis of the space (``dim``
        directional derivatives, then an LU solve per member): the choice for small ``n``.
        ``"krylov"`` solves each Newton system matrix-free with GMRES (Newton–Krylov), for large
        ``n``.
    rtol, atol, max_iter, stall_rtol, divergence_factor
        As for :class:`FixedPoint`.
    krylov_rtol : float
        Relative tolerance of each GMRES solve (inexact Newton: the outer residual test alone
        decides convergence, so a loose inner tolerance costs outer iterations, not accuracy).
    krylov_max_restarts : int
        Restart cycles of GMRES (each of at most ``min(dim, 30)`` iterations) per Newton step.

    Notes
    -----
    ``DG`` is exact when the problem supplies the derivative of ``B`` (``B_jvp``), otherwise a
    forward finite difference; the fixed point reached is the same either way (the residual is
    exact), only the rate differs.

    Newton is far more robust than fixed-point iteration for large ``h ||B||``, but there the
    implicit equation has several roots and Newton may converge to one off the branch that
    tends to ``W_k`` as ``h -> 0`` (e.g. on so(4) at ``h ||B|| ~ 10``: Casimirs exact, energy
    off by 25%). Such a step is a solution of the scheme, not a consistent one: keep
    ``h ||B(W)||`` moderate whatever the solver.
    """

    jacobian: Literal["dense", "krylov"] = "dense"
    rtol: float = 1e-14
    atol: float = 0.0
    max_iter: int = 50
    stall_rtol: float = 1e-12
    divergence_factor: float = 1e4
    krylov_rtol: float = 1e-7
    krylov_max_restarts: int = 3

    def __post_init__(self) -> None:
        if self.jacobian not in ("dense", "krylov"):
            raise ValueError(f"jacobian must be 'dense' or 'krylov', got {self.jacobian!r}")
        _StoppingRules(
            self.rtol, self.atol, self.max_iter, self.stall_rtol, self.divergence_factor
        ).check()

    def _jvp(self, prob: FixedPointProblem, X: Array, GX: Array, dX: Array, mask: Array | None):
        if prob.jvp is not None:
            return prob.jvp(X, dX, mask)
        alg = prob.algebra
        nx = np.maximum(alg.norm(X), 1.0)
        nd = np.maximum(alg.norm(dX), np.finfo(float).tiny)
        eps = (np.sqrt(np.finfo(float).eps) * nx / nd).reshape(nx.shape + (1,) * alg.core_ndim)
        Gp, _ = prob.G(X + eps * dX, mask)
        return (Gp - GX) / eps

    def _update(self, prob: FixedPointProblem, X: Array, GX: Array, mask: Array | None) -> Array:
        alg = prob.algebra
        rhs = alg.to_coords(GX - X)  # Newton: (I - DG) d = G(X) - X
        if self.jacobian == "dense":
            basis = alg.from_coords(np.eye(alg.dim))  # (dim, *shape)
            cols = []
            for j in range(alg.dim):
                E = np.broadcast_to(basis[j], X.shape)
                cols.append(alg.to_coords(E - self._jvp(prob, X, GX, E, mask)))
            J = np.stack(cols, axis=-1)  # (*b, dim, dim)
            d = np.linalg.solve(J, rhs[..., None])[..., 0]
            return alg.project(X + alg.from_coords(d))
        # matrix-free Newton-Krylov, member by member
        batch = alg.batch_shape(X)
        Xf = X.reshape(-1, *alg.shape)
        GXf = GX.reshape(-1, *alg.shape)
        rf = rhs.reshape(-1, alg.dim)
        out = np.empty_like(Xf)
        for i in range(Xf.shape[0]):
            xi, gi = Xf[i : i + 1], GXf[i : i + 1]
            sub_mask = _single_member_mask(mask, batch, i)

            def matvec(v: Array, xi: Array = xi, gi: Array = gi, m: Array | None = sub_mask):
                E = alg.from_coords(v[None, :])
                return alg.to_coords(E - self._jvp(prob, xi, gi, E, m))[0]

            op = spla.LinearOperator((alg.dim, alg.dim), matvec=matvec, dtype=np.float64)
            d, _info = spla.gmres(
                op,
                rf[i],
                rtol=self.krylov_rtol,
                atol=0.0,
                restart=min(alg.dim, 30),
                maxiter=self.krylov_max_restarts,
            )
            out[i] = xi[0] + alg.from_coords(d)
        return alg.project(out.reshape(X.shape))


def _single_member_mask(mask: Array | None, batch: tuple[int, ...], i: int) -> Array | None:
    """Boolean mask over the batch selecting the ``i``-th member of the current selection."""
    if mask is None:
        if batch == ():
            return None
        full = np.zeros(int(np.prod(batch)), dtype=bool)
        full[i] = True
        return full.reshape(batch)
    idx = np.flatnonzero(mask)[i]
    sub = np.zeros(mask.size, dtype=bool)
    sub[idx] = True
    return sub.reshape(mask.shape)
