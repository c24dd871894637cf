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

Acceleration
------------
:class:`FixedPoint` can mix the last iterates (Anderson acceleration, type II; Walker & Ni,
SIAM J. Numer. Anal. 49 (2011) 1715–1735). With memory ``m``, residuals
:math:`f_k = G(X_k) - X_k` and the differences :math:`\Delta f_j = f_{j+1} - f_j`,
:math:`\Delta G_j = G(X_{j+1}) - G(X_j)` of the last ``m_k = \min(m, k)`` iterations,

.. math::

    \gamma = \arg\min_\gamma \Big\| f_k - \sum_j \gamma_j \Delta f_j \Big\|, \qquad
    X_{k+1} = G(X_k) - \sum_j \gamma_j\, \Delta G_j ,

with the real inner product of the space, so :math:`\gamma` is real and :math:`X_{k+1}` a
real combination of values of ``G``: it stays in the stage space. The least-squares problem is
solved by its normal equations, regularized by ``1e-12`` times the largest diagonal entry. The
stopping rules above are unchanged (they test :math:`\|f_k\|`); with ``m = 0`` this is the plain
iteration :math:`X_{k+1} = G(X_k)`. The compiled loops (:mod:`isoflow._compiled`) run the same
algorithm.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from . import _failures
from ._errors import ParameterError
from .algebras import Algebra

__all__ = [
    "ANDERSON_MAX",
    "CONTINUE",
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

#: The solvers' status codes (:mod:`isoflow._failures` holds the whole vocabulary).
STATUS_CONVERGED = _failures.CONVERGED
STATUS_MAX_ITER = _failures.MAX_ITER
STATUS_DIVERGED = _failures.DIVERGED
STATUS_NON_FINITE = _failures.NON_FINITE

#: Returned by :func:`stopping_step` while the iteration goes on (not a status of a result).
CONTINUE = -1

#: Regularization of Anderson's normal equations, relative to their largest diagonal entry.
ANDERSON_REGULARIZATION = 1e-12

#: Largest Anderson memory of :class:`FixedPoint` (the one statement of the bound: the run
#: configurations, ``isoflow run --anderson`` and ``isoflow demo --anderson`` check against it).
ANDERSON_MAX = 8


def stopping_step(
    r: float, prev: float, first: float, it: int, tol: float, floor: float, divergence: float
) -> tuple[int, float, float]:
    """The stopping rules of the module for one member at iteration ``it`` (1-based).

    ``r`` is the current residual, ``prev`` the previous one (``inf`` at the first
    iteration), ``first`` the first one (``inf`` before it), ``tol = atol + rtol s`` and
    ``floor = stall_rtol s``. Returns ``(code, prev, first)``: a ``STATUS_*`` code
    (:data:`CONTINUE` to go on) and the ``prev`` and ``first`` to pass at the next
    iteration. This one function is the rule everywhere: the Python solvers call it, the
    compiled driver (:mod:`isoflow._compiled.driver`) uses a numba compilation of it.
    """
    if not math.isfinite(r):
        code = STATUS_NON_FINITE
    elif r <= tol or (r >= prev and r <= floor):
        code = STATUS_CONVERGED
    elif it > 1 and r > divergence * first:
        code = STATUS_DIVERGED
    else:
        code = CONTINUE
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
    gx : ndarray
        ``G(x)``, the map's last value per member: closer to the fixed point than ``x`` by the
        map's contraction (IsoMP extrapolates its next start from it).
    """

    x: Array
    aux: Array
    iterations: NDArray[np.int64]
    residual: NDArray[np.float64]
    status: NDArray[np.int64]
    gx: Array

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
        for name in ("rtol", "atol", "stall_rtol", "divergence_factor"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
                raise ParameterError(f"{name} must be a real number, got {v!r}")
            if not math.isfinite(v) or v < 0:
                raise ParameterError(f"{name} must be finite and non-negative, got {v!r}")
        if self.rtol + self.atol <= 0:
            raise ParameterError("tolerances rtol and atol must not both be zero")
        if self.divergence_factor <= 1:
            raise ParameterError(f"divergence_factor must be > 1, got {self.divergence_factor!r}")
        m = self.max_iter
        if isinstance(m, bool) or not isinstance(m, (int, np.integer)) or m < 1:
            raise ParameterError(f"max_iter must be an integer >= 1, got {m!r}")


class NonlinearSolver:
    """Common driver: iterate ``update`` per member under the stopping rules of the module."""

    rtol: float
    atol: float
    max_iter: int
    stall_rtol: float
    divergence_factor: float

    #: Anderson memory (0: none); :class:`FixedPoint` sets it.
    anderson: int = 0

    def _update(
        self, prob: FixedPointProblem, X: Array, GX: Array, mask: Array | None
    ) -> Array:  # pragma: no cover - abstract
        raise NotImplementedError

    def solve(self, prob: FixedPointProblem, X0: Array) -> NonlinearResult:
        """Solve ``X = G(X)`` starting from ``X0`` (not modified).

        Overflow and NaN in a diverging member are reported by its status, not as NumPy
        warnings.

        Parameters
        ----------
        prob : FixedPointProblem
            The map ``G``, its space, the scale of the tolerances and (for Newton) the
            Jacobian-vector product.
        X0 : ndarray, shape (*batch, *shape)
            The initial guess (one member or an ensemble; not modified).

        Returns
        -------
        NonlinearResult
            The solution and, per member, the iterations, the residual and the status.
        """
        with np.errstate(over="ignore", invalid="ignore"):
            if prob.algebra.batch_shape(X0) == ():
                return self._solve_single(prob, X0)
            return self._solve(prob, X0)

    def _solve(self, prob: FixedPointProblem, X0: Array) -> NonlinearResult:
        alg = prob.algebra
        batch = alg.batch_shape(X0)
        core = alg.shape
        M = int(np.prod(batch))
        X = np.array(X0, dtype=alg.dtype, copy=True).reshape(M, *core)
        iters = np.zeros(M, dtype=np.int64)
        resid = np.full(M, np.inf)
        status = np.full(M, CONTINUE, dtype=np.int64)
        first = np.full(M, np.nan)
        scale = np.broadcast_to(np.asarray(prob.scale, dtype=float), batch).reshape(M)
        tol = self.atol + self.rtol * scale
        floor = self.stall_rtol * scale
        aux: Array | None = None
        gx = np.empty_like(X)
        mixer = _Anderson(self.anderson, M) if self.anderson > 0 else None
        active = np.arange(M)
        for it in range(self.max_iter):
            whole = active.size == M
            mask = None if whole else _batch_mask(active, batch)
            Xa = X if whole else X[active]
            Xin = Xa.reshape(*batch, *core) if whole else Xa  # what G (and Newton) expect
            GXin, aux_a = prob.G(Xin, mask)
            GX = GXin.reshape(active.size, *core)
            aux_a = aux_a.reshape(active.size, *aux_a.shape[aux_a.ndim - len(core) :])
            r = alg.norm(GX - Xa)
            if aux is None:
                aux = np.zeros((M, *aux_a.shape[1:]), dtype=aux_a.dtype)
            prev = resid[active]
            r0 = np.where(np.isnan(first[active]), r, first[active])
            first[active] = r0
            tol_a, floor_a = tol[active], floor[active]
            iters[active] += 1
            resid[active] = r
            aux[active] = aux_a
            done_ok = (r <= tol_a) | ((r >= prev) & (r <= floor_a))
            non_finite = ~np.isfinite(r)
            diverged = (r > self.divergence_factor * r0) & (r > tol_a) & ~non_finite
            st = np.full(r.shape, CONTINUE, dtype=np.int64)
            st[done_ok] = STATUS_CONVERGED
            st[diverged] = STATUS_DIVERGED
            st[non_finite] = STATUS_NON_FINITE
            status[active] = st
            going = st == CONTINUE
            # G at each member's last iterate: kept when it stops (or the iterations run out)
            last = ~going if it + 1 < self.max_iter else slice(None)
            gx[active[last]] = GX[last]
            if not going.any():
                active = active[going]
                break
            sub = active[going]
            Xg, Gg = Xa[going], GX[going]
            if mixer is not None:
                X[sub] = mixer.mix(sub, Xg, Gg)
            else:
                Xn = self._update(prob, Xin, GXin, mask).reshape(active.size, *core)
                X[sub] = Xn[going]
            active = sub
        status[status == CONTINUE] = STATUS_MAX_ITER
        assert aux is not None
        return NonlinearResult(
            x=X.reshape(*batch, *core),
            aux=aux.reshape(*batch, *aux.shape[1:]),
            iterations=iters.reshape(batch),
            residual=resid.reshape(batch),
            status=status.reshape(batch),
            gx=gx.reshape(*batch, *core),
        )

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
        GX = X
        mixer = _Anderson(self.anderson, 1) if self.anderson > 0 else None
        for it in range(1, self.max_iter + 1):
            GX, aux = prob.G(X, None)
            r = float(prob.algebra.norm(GX - X))  # as for ensembles: the same decisions
            code, prev, first = stopping_step(
                r, prev, first, it, tol, floor, self.divergence_factor
            )
            if code != CONTINUE:
                status = code
                break
            if mixer is not None:
                X = mixer.mix(np.zeros(1, dtype=np.int64), X[None], GX[None])[0]
            else:
                X = self._update(prob, X, GX, None)
        assert aux is not None
        return NonlinearResult(
            x=X,
            aux=aux,
            iterations=np.asarray(it, dtype=np.int64),
            residual=np.asarray(r),
            status=np.asarray(status, dtype=np.int64),
            gx=GX,
        )


def _batch_mask(active: Array, batch: tuple[int, ...]) -> Array:
    """Boolean mask over the batch axes selecting the flat member indices ``active``."""
    mask = np.zeros(int(np.prod(batch)), dtype=bool)
    mask[active] = True
    return mask.reshape(batch)


class _Anderson:
    """Anderson mixing (type II, memory ``m``) for the members of one nonlinear solve.

    Every member starts at the first iteration, so all members still iterating share the
    length of their history; the arrays hold every member (first axis) and are updated at the
    rows of the members that go on.
    """

    def __init__(self, m: int, members: int) -> None:
        self.m = m
        self.members = members
        self.dF: list[Array] = []  # oldest first
        self.dG: list[Array] = []
        self.f_prev: Array | None = None
        self.g_prev: Array | None = None

    def _inner(self, A: Array, B: Array) -> Array:
        axes = tuple(range(1, A.ndim))
        return np.real(np.sum(np.conj(A) * B, axis=axes))

    def mix(self, rows: Array, X: Array, G: Array) -> Array:
        """The next iterates of the members ``rows`` (their ``X`` and ``G(X)`` given)."""
        f = G - X
        if self.f_prev is None:
            self.f_prev = np.zeros((self.members, *f.shape[1:]), dtype=f.dtype)
            self.g_prev = np.zeros_like(self.f_prev)
            self.f_prev[rows] = f
            self.g_prev[rows] = G
            return G
        assert self.g_prev is not None
        dF = np.zeros_like(self.f_prev)
        dG = np.zeros_like(self.g_prev)
        dF[rows] = f - self.f_prev[rows]
        dG[rows] = G - self.g_prev[rows]
        self.dF.append(dF)
        self.dG.append(dG)
        if len(self.dF) > self.m:
            self.dF.pop(0)
            self.dG.pop(0)
        self.f_prev[rows] = f
        self.g_prev[rows] = G
        k = len(self.dF)
        Fs = [d[rows] for d in self.dF]
        A = np.empty((rows.size, k, k))
        for i in range(k):
            for j in range(i, k):
                A[:, i, j] = A[:, j, i] = self._inner(Fs[i], Fs[j])
        b = np.stack([self._inner(Fi, f) for Fi in Fs], axis=-1)
        gamma = _regularized_solve(A, b)
        out = G.copy()
        for j in range(k):
            g = gamma[:, j].reshape((rows.size,) + (1,) * (G.ndim - 1))
            out -= g * self.dG[j][rows]
        return out


def _regularized_solve(A: Array, b: Array) -> Array:
    """Solve ``(A + lambda I) x = b`` per member, ``lambda = 1e-12 max diag A`` (0 if A = 0)."""
    k = A.shape[-1]
    diag = np.max(np.diagonal(A, axis1=-2, axis2=-1), axis=-1)
    lam = ANDERSON_REGULARIZATION * diag
    ok = diag > 0
    Ar = A + lam[:, None, None] * np.eye(k)
    Ar[~ok] = np.eye(k)
    x = np.linalg.solve(Ar, b[..., None])[..., 0]
    x[~ok] = 0.0
    return x


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
    anderson : int
        Anderson memory ``m`` from 0 (the plain iteration) to :data:`ANDERSON_MAX`; see the
        module docstring. Mixing the last ``m`` iterates costs ``O(m)`` inner products per
        iteration and usually saves iterations when many are needed (large ``h ||B||``, tight
        tolerances).
    """

    rtol: float = 1e-14
    atol: float = 0.0
    max_iter: int = 200
    stall_rtol: float = 1e-12
    divergence_factor: float = 1e4
    anderson: int = 0

    def __post_init__(self) -> None:
        _StoppingRules(
            self.rtol, self.atol, self.max_iter, self.stall_rtol, self.divergence_factor
        ).check()
        m = self.anderson
        if (
            isinstance(m, bool)
            or not isinstance(m, (int, np.integer))
            or not 0 <= m <= ANDERSON_MAX
        ):
            raise ParameterError(
                f"anderson must be an integer memory in [0, {ANDERSON_MAX}], got {m!r}"
            )

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
            raise ParameterError(f"jacobian must be 'dense' or 'krylov', got {self.jacobian!r}")
        _StoppingRules(
            self.rtol, self.atol, self.max_iter, self.stall_rtol, self.divergence_factor
        ).check()
        r = self.krylov_rtol
        if (
            isinstance(r, bool)
            or not isinstance(r, (int, float, np.integer, np.floating))
            or not 0 < r < 1
        ):
            raise ParameterError(f"krylov_rtol must be a real number in (0, 1), got {r!r}")
        m = self.krylov_max_restarts
        if isinstance(m, bool) or not isinstance(m, (int, np.integer)) or m < 1:
            raise ParameterError(f"krylov_max_restarts must be an integer >= 1, got {m!r}")

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

            import scipy.sparse.linalg as spla  # Newton-Krylov only: not at import

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
