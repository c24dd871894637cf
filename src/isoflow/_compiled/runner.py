r"""The compiled runner: which driver and stage a run gets, and the chunks it runs.

:func:`compiled_runner` is what the time loop asks first. It returns a :class:`CompiledRunner`
when the run has a compiled path, ``None`` otherwise (the time loop then steps with the
method's own code, :class:`~isoflow._stepping.PythonRunner`). A compiled path exists for

* a problem with a kernel (:mod:`isoflow.kernels`: your ``CompiledB`` or a built-in one),
* the fixed-point solver (:class:`~isoflow.FixedPoint`, plain or Anderson-accelerated),
* :class:`~isoflow.IsoMP` on ``so(n)``, ``u(n)``, ``su(n)``, ``Sym(n)``, ``Herm(n)`` (any
  ``n``: written-out products up to :data:`~isoflow._compiled.dense.SMALL_N`, BLAS above),
  on :math:`(\mathbb{R}^3,\times)^N` and on :math:`(\mathbb{R}^3,\times_L)^N`;
  :class:`~isoflow.SphericalMidpoint` on :math:`(\mathbb{R}^3,\times)^N`; single systems and
  ensembles (members over numba threads).

Two kernels keep a specialized evaluation where benchmarks show it pays: an
:class:`~isoflow.ElementwiseLinear` kernel with a frame runs in the frame where ``B`` is
entrywise (IsoMP commutes with the change of frame), and :class:`~isoflow.SpinNeighbourSum`
runs the fused spin-chain sweeps in a ``(3, N)`` layout (:mod:`isoflow._compiled.spin_chain`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._errors import IsoflowError
from .._stepping import FAIL_B_RAISED, MemberFailures, Runner
from ..algebras import Hermitian, SL2Vectors, SpecialOrthogonal, SpinVectors, Symmetric, Unitary
from ..kernels import CompiledB, ElementwiseLinear, PairwiseVortex, SpinNeighbourSum
from ..methods import Composition, IsoMP, Method, SphericalMidpoint
from ..methods import composition as _composition
from ..methods.isomp import extrapolation_weights
from ..nonlinear import FixedPoint
from ..problems import IsospectralProblem
from . import blocked, dense, driver, particles, spin_chain, vortices
from .rules import ANDERSON_REGULARIZATION

__all__ = ["CompiledRunner", "Layout", "compiled_runner", "sigma_sign"]

Array = NDArray[Any]

#: Smallest spin chain whose sweeps are cut into chunks over numba threads.
PARALLEL_MIN_SPINS = 200_000
#: Smallest ensemble of an elementwise kernel run in the blocked (SIMD over members) layout.
BLOCKED_MIN_MEMBERS = 8


def sigma_sign(alg: Any) -> float | None:
    r"""``s`` with :math:`\sigma(Y) = s\,\bar Y^T` for the dense spaces with a compiled path
    (``su(n)`` is ``u(n)`` plus the trace removal of its projection), else ``None``."""
    if isinstance(alg, (SpecialOrthogonal, Unitary)):
        return -1.0
    if isinstance(alg, (Symmetric, Hermitian)):
        return 1.0
    return None


#: Compiled drivers of this process by :meth:`CompiledRunner._driver`'s key.
_DRIVERS: dict[Any, Any] = {}


def _type_key(x: Any) -> Any:
    """What numba types an argument by (arrays: dtype, dimensions, layout, writability)."""
    if isinstance(x, np.ndarray):
        return ("array", x.dtype.str, x.ndim, x.flags.c_contiguous, x.flags.writeable)
    if isinstance(x, tuple):
        return tuple(_type_key(v) for v in x)
    return type(x)


def _threads() -> int:
    import numba

    return int(numba.get_num_threads())


@dataclass(frozen=True)
class Layout:
    """How a run's states are laid out for its compiled stage, and the stage itself.

    Attributes
    ----------
    name : str
        For messages (``"dense (written-out products)"``, ...).
    iterate, finish : numba dispatchers
        The stage functions (interface of :mod:`isoflow._compiled.driver`).
    sp : tuple
        Their parameters.
    nwork : int
        Scratch rows per member.
    to_flat : callable
        ``(M, *core)`` user states -> a new ``(M, S)`` array in the stage's layout.
    from_flat : callable
        ``(..., M, S)`` -> ``(..., M, *core)`` states in the user's layout (projected onto the
        space where the layout is a change of frame).
    offsets_from_flat : callable
        The same for stage offsets (projected onto the stage space).
    identity : bool
        Whether the layout is the user's (a reshape, no copy or change of frame).
    field : (f, args) or None
        The field to call instead of the kernel's (the entrywise one inside a frame).
    restart_at_saves : bool
        The layout's change of variables is not exact in floating point (a frame): the state
        and the offsets are mapped to the user's layout and back at every save point, so that
        a run restarted from a saved state (a checkpoint) continues it bit for bit. Before the
        first save point, the runner exports exactly the state and offsets it was given.
    """

    name: str
    iterate: Any
    finish: Any
    sp: tuple[Any, ...]
    nwork: int
    to_flat: Callable[[Array], Array]
    from_flat: Callable[[Array], Array]
    offsets_from_flat: Callable[[Array], Array]
    identity: bool = True
    field: tuple[Any, tuple[Any, ...]] | None = None
    restart_at_saves: bool = False


def _load_scipy_blas() -> None:
    """Load the BLAS the BLAS stage calls (numba's ``np.dot`` binds SciPy's cython BLAS, a
    library of its own besides NumPy's) before the run starts, so that the run's thread limits
    reach it from the first step (:mod:`isoflow.threads`)."""
    import scipy.linalg.cython_blas  # noqa: F401


def _plain(core: tuple[int, ...], dtype: Any) -> dict[str, Any]:
    def to_flat(Y: Array) -> Array:
        return np.array(Y, dtype=dtype, order="C", copy=True).reshape(Y.shape[0], -1)

    def from_flat(A: Array) -> Array:
        return A.reshape(*A.shape[:-1], *core)

    return {"to_flat": to_flat, "from_flat": from_flat, "offsets_from_flat": from_flat}


def _dense_layout(problem: IsospectralProblem, kernel: Any) -> Layout | None:
    alg = problem.algebra
    s = sigma_sign(alg)
    if s is None:
        return None
    n = alg.shape[0]
    traceless = bool(getattr(alg, "traceless", False))
    maps = _plain(alg.shape, alg.dtype)
    identity = True
    if isinstance(kernel, ElementwiseLinear) and kernel.frame is not None:
        U = kernel.frame.astype(alg.dtype) if alg.is_complex else kernel.frame
        Uh = np.ascontiguousarray(U.conj().T)
        stage = alg.stage_algebra

        def to_flat(Y: Array) -> Array:
            return np.ascontiguousarray(Uh @ Y @ U, dtype=alg.dtype).reshape(Y.shape[0], -1)

        def back(space: Any) -> Callable[[Array], Array]:
            def f(A: Array) -> Array:
                M = A.reshape(*A.shape[:-1], n, n)
                return np.asarray(space.project(U @ M @ Uh))

            return f

        maps = {"to_flat": to_flat, "from_flat": back(alg), "offsets_from_flat": back(stage)}
        maps["field"] = ElementwiseLinear(kernel.coeff).field()
        maps["restart_at_saves"] = True
        identity = False
    if n <= dense.SMALL_N:
        return Layout(
            f"dense {alg.name} (written-out products)", dense.iterate_small, dense.finish,
            (n, s, traceless), 3, identity=identity, **maps,
        )  # fmt: skip
    _load_scipy_blas()
    blocks, rowoff = dense.packed_row_offsets(n)
    return Layout(
        f"dense {alg.name} (BLAS)", dense.iterate_blas, dense.finish_blas,
        (n, s, traceless, rowoff, blocks), 3, identity=identity, **maps,
    )  # fmt: skip


def _chain_layout(N: int, coupling: float, smm: bool) -> Layout:
    par = N >= PARALLEL_MIN_SPINS and _threads() > 1
    nch = 8 * _threads() if par else 1
    if smm:
        it = spin_chain.iterate_smm_par if par else spin_chain.iterate_smm_ser
        fin = spin_chain.finish_smm
    else:
        it = spin_chain.iterate_iso_par if par else spin_chain.iterate_iso_ser
        fin = spin_chain.finish_iso

    def to_flat(Y: Array) -> Array:
        return np.ascontiguousarray(np.swapaxes(Y, -1, -2), dtype=np.float64).reshape(
            Y.shape[0], -1
        )

    def from_flat(A: Array) -> Array:
        return np.swapaxes(A.reshape(*A.shape[:-1], 3, N), -1, -2)

    return Layout(
        f"spin chain (fused sweeps{', threaded' if par else ''})", it, fin,
        (N, float(coupling), nch), 1, to_flat, from_flat, from_flat, identity=False,
    )  # fmt: skip


def _particle_layout(problem: IsospectralProblem, smm: bool) -> Layout | None:
    alg = problem.algebra
    kernel = problem.kernel
    N = alg.shape[0]
    if isinstance(kernel, PairwiseVortex):  # checked against the space with the problem
        sphere = kernel.geometry == "sphere"
        if smm and not sphere:
            return None
        it = (
            vortices.iterate_sphere_smm if smm
            else vortices.iterate_sphere if sphere
            else vortices.iterate_hyperbolic
        )  # fmt: skip
        return Layout(
            f"point vortices ({kernel.geometry}, fused pairs)", it, particles.finish, (N,),
            2 if smm else 1, **_plain(alg.shape, np.float64),
        )  # fmt: skip
    if type(alg) is SpinVectors:
        if isinstance(kernel, SpinNeighbourSum) and N >= 2:
            return _chain_layout(N, kernel.coupling, smm)
        it = particles.iterate_smm if smm else particles.iterate_so3
        return Layout(
            "(R^3, x)^N", it, particles.finish, (N,), 2 if smm else 1,
            **_plain(alg.shape, np.float64),
        )  # fmt: skip
    if type(alg) is SL2Vectors and not smm:
        return Layout(
            "(R^3, x_L)^N", particles.iterate_sl2, particles.finish, (N,), 1,
            **_plain(alg.shape, np.float64),
        )  # fmt: skip
    return None


def _extrapolation(method: Method) -> int:
    """Offsets kept for the initial guess (0: start from the state)."""
    if isinstance(method, IsoMP):
        return method.extrapolation_order + 1 if method.initial_guess == "extrapolate" else 0
    if isinstance(method, SphericalMidpoint):
        return 1 if method.initial_guess == "extrapolate" else 0
    return 0


def compiled_runner(
    problem: IsospectralProblem, method: Method, y: Array, h: float, *,
    method_state: Any = None, k: int = 0, failures: MemberFailures | None = None,
) -> CompiledRunner | None:  # fmt: skip
    """A :class:`CompiledRunner` for the run, or ``None`` when it has no compiled path."""
    kernel = problem.kernel
    if kernel is None:
        return None
    base: Any = method
    gammas_t: tuple[float, ...] = (1.0,)
    if isinstance(method, Composition):
        base, gammas_t = method.base, tuple(method.coefficients)
    if not isinstance(base, (IsoMP, SphericalMidpoint)):
        return None
    if type(base.solver) is not FixedPoint:
        return None
    alg = problem.algebra
    y = np.asarray(y)
    if y.dtype != alg.dtype:
        return None
    smm = isinstance(base, SphericalMidpoint)
    if smm:
        layout = _particle_layout(problem, smm=True)
    elif sigma_sign(alg) is not None:
        layout = _dense_layout(problem, kernel)
    else:
        layout = _particle_layout(problem, smm=False)
    if layout is None:
        return None
    M = int(np.prod(alg.batch_shape(y), dtype=np.int64))
    if (
        isinstance(kernel, ElementwiseLinear)
        and layout.iterate is dense.iterate_small
        and M >= BLOCKED_MIN_MEMBERS
        and base.solver.anderson == 0
        and len(gammas_t) == 1
    ):
        return BlockedRunner(
            layout, problem, base, y, h, method_state=method_state, k=k, failures=failures
        )
    return CompiledRunner(
        layout, problem, base, np.asarray(gammas_t, dtype=np.float64), y, h,
        method_state=method_state, k=k, failures=failures,
        composed=isinstance(method, Composition),
    )  # fmt: skip


class CompiledRunner(Runner):
    """Runs chunks of steps of a :class:`Layout` through the one compiled driver.

    See :class:`~isoflow._stepping.Runner` for the protocol. The states, the ring of stage
    offsets and the per-member records live in this object's arrays between calls.
    """

    def __init__(
        self, layout: Layout, problem: IsospectralProblem, method: Any, gammas: Array,
        y: Array, h: float, *, method_state: Any = None, k: int = 0,
        failures: MemberFailures | None = None, composed: bool = False,
    ) -> None:  # fmt: skip
        super().__init__()
        alg = problem.algebra
        self.composed = composed
        self.layout = layout
        self.label = f"compiled, {layout.name}"
        self.core = alg.shape
        self.batch = alg.batch_shape(y)
        self.M = int(np.prod(self.batch, dtype=np.int64))
        self.h = float(h)
        self.k = int(k)
        self.failures = failures if failures is not None else MemberFailures.none(self.M)
        self.kernel = problem.kernel
        self.algebra = alg
        field = layout.field or problem.kernel.field()  # type: ignore[union-attr]
        self.f: Any = field[0]
        self.fargs: tuple[Any, ...] = field[1]
        solver = method.solver
        self.solver = solver
        self.kmax = _extrapolation(method)
        K = max(self.kmax, 1)
        self.coefs = np.zeros((K, K))
        for m in range(1, K + 1):
            self.coefs[m - 1, :m] = extrapolation_weights(m)
        self.gammas = gammas
        P = gammas.shape[0]
        self.W = layout.to_flat(np.asarray(y).reshape(self.M, *self.core))
        S = self.W.shape[1]
        self.S = S
        self.ring = np.zeros((self.M, P, K, S), dtype=self.W.dtype)
        self.head = np.zeros((self.M, P), dtype=np.int64)
        self.nh = np.zeros((self.M, P), dtype=np.int64)
        self._user: tuple[int, Array, Array] | None = None
        if layout.restart_at_saves:  # what state() exports before the first save point
            user = np.zeros((P, K, self.M, *self.core), dtype=self.W.dtype)
            self._load_offsets(method_state, user)
            self._user = (self.k, np.array(y, copy=True).reshape(self.M, *self.core), user)
        else:
            self._load_offsets(method_state)
        self.rec = np.zeros((self.M, driver.REC_SIZE))
        self.rec[:, driver.REC_FAIL_STEP] = np.where(
            self.failures.step >= 0, self.failures.step + 1, -1
        )
        self.parallel = self.M >= 2 and _threads() > 1 and self._threads_allowed()
        self._drive: Any = None

    def _threads_allowed(self) -> bool:
        """Members may run on numba threads unless they call a multithreaded BLAS (the BLAS
        threads in force: those of the run's thread plan, :mod:`isoflow.threads`)."""
        if self.layout.iterate is not dense.iterate_blas:
            return True
        from ..threads import blas_threads

        return blas_threads() <= 1

    # ---- method state <-> ring ---------------------------------------------------------------
    def _position_states(self, state: Any) -> list[Any]:
        """The base method's state of every substep position (one, unless composed)."""
        P = self.gammas.shape[0]
        return _composition._unpack(state, P) if self.composed else [state]

    def _load_offsets(self, state: Any, user: Array | None = None) -> None:
        """The ring from the method state's offsets (user's layout); with ``user``
        (``(P, K, M, *core)``), the given offsets are also kept there, slot by slot."""
        if self.kmax == 0:
            return
        for p, st in enumerate(self._position_states(state)):
            hp = float(self.gammas[p]) * self.h
            if st is None or len(st) < 2 or st[0] != hp:
                continue
            offsets = st[1 : 1 + self.kmax]
            nh = len(offsets)
            for q, D in enumerate(offsets):  # newest first
                Dm = np.asarray(D).reshape(self.M, *self.core)
                self.ring[:, p, (nh - 1 - q)] = self.layout.to_flat(Dm)
                if user is not None:
                    user[p, nh - 1 - q] = Dm
            self.head[:, p] = nh - 1
            self.nh[:, p] = nh

    def _export_offsets(self) -> Any:
        if self.kmax == 0:
            return None
        alive = self.failures.alive
        K = self.ring.shape[2]
        idx = np.arange(self.M)
        user = self._user if self._user is not None and self._user[0] == self.k else None
        states: list[Any] = []
        for p in range(self.gammas.shape[0]):
            nh_p = self.nh[alive, p] if alive.any() else self.nh[:, p]
            nh = int(nh_p.max())
            out: list[Any] = [float(self.gammas[p]) * self.h]
            for q in range(nh):
                slots = (self.head[:, p] - q) % K
                if user is not None:
                    D = user[2][p, slots, idx]
                else:
                    flat = self.ring[idx, p, slots]
                    D = np.array(self.layout.offsets_from_flat(flat), copy=True)
                out.append(D[0] if self.batch == () else D)  # members flattened, as PythonRunner
            states.append(tuple(out) if nh else None)
        return _composition._pack(states) if self.composed else states[0]

    def state(self) -> tuple[Array, Any]:
        if self._user is not None and self._user[0] == self.k:
            y = self._user[1].copy()
        else:
            y = np.array(self.layout.from_flat(self.W), copy=True)
        return y.reshape(*self.batch, *self.core), self._export_offsets()

    def B_at(self, rows: Array) -> Array:
        return self.kernel.evaluate(rows, self.algebra)  # type: ignore[union-attr]

    def freeze(self, m: int, step: int, y: Array, status: int, message: str) -> None:
        self.W[m] = self.layout.to_flat(np.asarray(y).reshape(1, *self.core))[0]
        if self._user is not None:
            self._user[1][m] = y
        self._mark_failed(m, step, status)
        self.failures.record(m, step, status, 0, float("nan"))
        self.failures.messages[m] = message

    def _mark_failed(self, m: int, step: int, status: int) -> None:
        """Member ``m``'s record: failed with ``status`` in the step from step ``step`` (the
        driver keeps it frozen from now on)."""
        rec = self.rec[m]
        rec[driver.REC_FAIL_STEP] = step + 1  # the driver counts steps from 1
        rec[driver.REC_FAIL_STATUS] = status
        rec[driver.REC_FAIL_ITERATIONS] = 0
        rec[driver.REC_FAIL_RESIDUAL] = np.nan

    # ---- running -----------------------------------------------------------------------------
    def _driver(self, parallel: bool | None = None) -> Any:
        """The compiled driver of this run (compiled, or loaded from numba's cache, once per
        process for each field, argument types, stage and ``parallel``, by default the run's:
        later runs reuse it at once)."""
        from .signatures import compiled_driver, stage_types

        parallel = self.parallel if parallel is None else parallel
        L = self.layout
        key = (self.f, _type_key(self.fargs), L.iterate, L.finish, _type_key(L.sp),
               self.W.dtype.str, parallel)  # fmt: skip
        drive = _DRIVERS.get(key)
        if drive is None:
            st = stage_types(self.f, self.fargs, L.sp, self.W.dtype)
            st.compile_stage(L.iterate, L.finish)
            drive = _DRIVERS[key] = compiled_driver(st.driver_signature(), parallel)
        return drive

    #: Checkpoints of this runner must fall on save points (see :attr:`Layout.restart_at_saves`).
    @property
    def checkpoints_at_saves(self) -> bool:
        return self.layout.restart_at_saves

    def advance(self, nsteps: int, save_every: int, k_final: int, out: Array) -> None:
        if not self.layout.restart_at_saves:
            self._advance(nsteps, save_every, k_final, out)
            return
        row = 0
        left = nsteps
        while left > 0 and self.failures.alive.any():
            k0 = self.k
            nxt = min((k0 // save_every + 1) * save_every, k_final)
            piece = min(left, max(nxt - k0, 1))
            r = 1 if (k0 + piece) % save_every == 0 or k0 + piece == k_final else 0
            self._advance(piece, save_every, k_final, out[row : row + r])
            row += r
            left -= piece
            if r:
                self._round_trip()

    def _round_trip(self) -> None:
        """Map the state and the offsets to the user's layout and back (at a save point);
        the user-layout values are kept: they are what :meth:`state` exports here, so that a
        restart from them maps them forward to exactly this runner's arrays."""
        L = self.layout
        y = np.array(L.from_flat(self.W), copy=True)
        self.W = np.ascontiguousarray(L.to_flat(y))
        P, K = self.ring.shape[1], self.ring.shape[2]
        user = np.empty((P, K, *y.shape), dtype=y.dtype)
        for p in range(P):
            for q in range(K):
                user[p, q] = L.offsets_from_flat(self.ring[:, p, q])
                self.ring[:, p, q] = L.to_flat(user[p, q])
        self._user = (self.k, y, user)

    def _rows_buffer(self, out: Array) -> Array:
        """Where the driver writes the saved rows: ``out`` itself when the layout is the
        user's and ``out`` is contiguous, else a flat buffer (see :meth:`_finish`). Also
        clears the per-call counters of the member records."""
        R = out.shape[0]
        rec = self.rec
        rec[:, driver.REC_ITERATIONS] = 0.0
        rec[:, driver.REC_ITERATIONS_MAX] = 0.0
        rec[:, driver.REC_RESIDUAL_MAX] = 0.0
        rec[:, driver.REC_CALL_DONE] = 0.0
        if self.layout.identity and out.flags.c_contiguous:
            return out.reshape(R, self.M, self.S)
        return np.empty((R, self.M, self.S), self.W.dtype)

    @property
    def _parallel_items(self) -> int:
        """What a parallel call spreads over the threads: the members."""
        return self.M

    @property
    def _chunk(self) -> int:
        """Items per piece of a parallel call, handed out to the threads as they come free:
        about 16 pieces per thread, so that a thread slowed by other work (the writer thread's
        diagnostics of the saved rows) leaves its remaining pieces to the others instead of
        holding up the end of the call. Members are independent: the pieces do not change
        any result."""
        return max(1, self._parallel_items // (16 * _threads()))

    def _call(self, make_drive: Any, args: tuple[Any, ...], what: str) -> None:
        """Run the compiled driver on ``args``; the first call gets it from ``make_drive()``
        and compiles it (or loads it from numba's cache; a compilation is announced as
        ``what``), later calls reuse it. A parallel driver hands out its items in pieces of
        :attr:`_chunk`."""
        import numba

        chunk = self._chunk if self.parallel else 0  # 0: numba's static split
        if self._drive is None:
            from .._compile_clock import compile_notice

            with compile_notice(f"the compiled loop for {what}"):
                drive = make_drive()
                self._drive = drive  # compiled: a raise from here on is the field's
                with numba.parallel_chunksize(chunk):
                    drive(*args)
        else:
            with numba.parallel_chunksize(chunk):
                self._drive(*args)

    def _finish(self, out: Array, buf: Array, nsteps: int) -> None:
        """Copy the rows from ``buf`` into ``out`` in the user's layout (unless the driver
        wrote them there) and take in the member records of the ``nsteps`` just run."""
        if out.shape[0] and not np.may_share_memory(out, buf):
            out[...] = self.layout.from_flat(buf)
        self._absorb(nsteps)

    def _args(
        self, members: slice, nsteps: int, k0: int, save_every: int, k_final: int, rows: Array
    ) -> tuple[Any, ...]:
        """The driver's arguments for the ``members`` (views of this runner's arrays) and
        ``nsteps`` steps from step ``k0``, their saved rows going into ``rows``."""
        L, s = self.layout, self.solver
        return (
            L.iterate, L.finish, self.f, self.fargs, L.sp, L.nwork,
            self.W[members], self.ring[members], self.head[members], self.nh[members],
            self.coefs, self.kmax, self.gammas,
            self.h, int(nsteps), int(k0), int(save_every), int(k_final), rows,
            float(s.rtol), float(s.atol), float(s.stall_rtol), float(s.divergence_factor),
            int(s.max_iter), int(s.anderson), ANDERSON_REGULARIZATION, self.rec[members],
        )  # fmt: skip

    def _advance(self, nsteps: int, save_every: int, k_final: int, out: Array) -> None:
        buf = self._rows_buffer(out)
        everyone = slice(None)
        args = self._args(everyone, nsteps, self.k, save_every, k_final, buf)
        what = f"{self.layout.name} with {getattr(self.f, '__name__', 'B')}"
        before = self._arrays(everyone) if self.may_raise else None
        raised: Exception | None = None
        try:
            self._call(self._driver, args, what)
        except Exception as exc:  # the field raised (a parallel driver says SystemError)
            if before is None or self._drive is None:
                raise
            raised = exc
        undone = np.flatnonzero(self.rec[:, driver.REC_CALL_DONE] == 0.0)
        if undone.size and before is not None:  # their field raised: redo them, alone
            for m in undone:
                self._set_arrays(slice(m, m + 1), tuple(a[m : m + 1] for a in before))
            self._isolate(undone, nsteps, save_every, k_final, buf)
        elif undone.size or raised is not None:
            raise IsoflowError(
                f"the compiled loop stopped {undone.size} member(s) in the middle of a chunk "
                f"without a result ({raised!r}); the run cannot go on"
            ) from raised
        self._finish(out, buf, nsteps)

    # ---- a field that raises: only the members whose B raises fail ---------------------------
    @property
    def may_raise(self) -> bool:
        """Whether the field is the user's (:class:`~isoflow.CompiledB`), which may raise: a
        chunk then keeps a copy of the arrays it changes, to redo the members after a raise."""
        return isinstance(self.kernel, CompiledB)

    def _arrays(self, members: slice) -> tuple[Array, ...]:
        """Copies of what a call changes for the ``members``."""
        return tuple(a[members].copy() for a in (self.W, self.ring, self.head, self.nh, self.rec))

    def _set_arrays(self, members: slice, saved: tuple[Array, ...]) -> None:
        for a, b in zip((self.W, self.ring, self.head, self.nh, self.rec), saved, strict=True):
            a[members] = b

    def _isolate(
        self, members: NDArray[np.intp], nsteps: int, save_every: int, k_final: int, buf: Array
    ) -> None:
        """Redo the chunk of the ``members`` whose call did not return, one by one (serially,
        each from its state before the call: the members' steps are independent, so every
        result equals a run without the raising members, bit for bit); a member whose ``B``
        raises is redone step by step and frozen at its last good state with
        :data:`FAIL_B_RAISED` at the step that raised."""
        drive = self._driver(parallel=False)
        rows = np.empty((buf.shape[0], 1, self.S), dtype=self.W.dtype)
        for m in members:
            one = slice(m, m + 1)
            saved = self._arrays(one)
            try:
                drive(*self._args(one, nsteps, self.k, save_every, k_final, rows))
            except Exception:
                self._set_arrays(one, saved)
                self._step_until_raise(m, drive, nsteps, save_every, k_final, buf)
            else:
                buf[:, m] = rows[:, 0]

    def _step_until_raise(
        self, m: int, drive: Any, nsteps: int, save_every: int, k_final: int, buf: Array
    ) -> None:
        """Member ``m``'s chunk one step per call until its field raises (see
        :meth:`_isolate`); its remaining rows repeat its last good state."""
        one = slice(m, m + 1)
        row = 0
        for k0 in range(self.k, self.k + nsteps):
            saves = 1 if (k0 + 1) % save_every == 0 or k0 + 1 == k_final else 0
            rows = np.empty((saves, 1, self.S), dtype=self.W.dtype)
            saved = self._arrays(one)
            try:
                drive(*self._args(one, 1, k0, save_every, k_final, rows))
            except Exception as exc:
                self._set_arrays(one, saved)
                self._fail_raised(m, k0, exc)
                buf[row:, m] = self.W[m]
                return
            buf[row : row + saves, m] = rows[:, 0]
            row += saves

    def _fail_raised(self, m: int, k0: int, exc: Exception) -> None:
        """Record that member ``m``'s field raised ``exc`` in the step from step ``k0``."""
        self._mark_failed(m, k0, FAIL_B_RAISED)
        self.failures.messages[m] = f"{type(exc).__name__}: {exc}"
        self.exceptions[m] = exc

    def _absorb(self, nsteps: int) -> None:
        rec = self.rec
        f = self.failures
        newly = np.flatnonzero((rec[:, driver.REC_FAIL_STEP] >= 0) & (f.step < 0))
        for m in newly:
            f.record(  # the driver counts steps from 1: step k goes from t_{k-1}
                int(m), int(rec[m, driver.REC_FAIL_STEP]) - 1, int(rec[m, driver.REC_FAIL_STATUS]),
                int(rec[m, driver.REC_FAIL_ITERATIONS]), float(rec[m, driver.REC_FAIL_RESIDUAL]),
            )  # fmt: skip
        its = int(rec[:, driver.REC_ITERATIONS].sum())
        self.iterations_total += its
        self.b_evaluations += its
        self.iterations_max = max(self.iterations_max, int(rec[:, driver.REC_ITERATIONS_MAX].max()))
        self.residual_max = max(self.residual_max, float(rec[:, driver.REC_RESIDUAL_MAX].max()))
        k_end = self.k + nsteps
        if not f.alive.any():  # every member failed: the run ends where the last one failed
            k_end = min(k_end, int(f.step.max()))
        self.k = k_end


class BlockedRunner(CompiledRunner):
    """An ensemble of an elementwise kernel in the blocked layout (:mod:`.blocked`)."""

    def __init__(
        self, layout: Layout, problem: IsospectralProblem, method: Any, y: Array, h: float, *,
        method_state: Any = None, k: int = 0, failures: MemberFailures | None = None,
    ) -> None:  # fmt: skip
        super().__init__(
            layout, problem, method, np.ones(1), y, h, method_state=method_state, k=k,
            failures=failures,
        )  # fmt: skip
        self.label = f"compiled, {layout.name}, blocks of {blocked.LANES} members"
        kernel = problem.kernel
        assert isinstance(kernel, ElementwiseLinear)
        self.coeff = np.ascontiguousarray(kernel.coeff)
        n = self.core[0]
        self.n = n
        nb = -(-self.M // blocked.LANES)
        self.nb = nb
        self.hn = np.zeros((nb, 2), dtype=np.int64)
        self._blocks_from_members()
        valid = np.zeros(nb * blocked.LANES, dtype=np.bool_)
        valid[: self.M] = True
        self.valid = valid.reshape(nb, blocked.LANES)
        self.parallel = nb >= 2 and _threads() > 1

    @property
    def _parallel_items(self) -> int:
        """What a parallel call spreads over the threads: the blocks of members."""
        return self.nb

    def _blocks_from_members(self) -> None:
        """The blocks (state, ring, head) from the member arrays."""
        n, nb = self.n, self.nb
        self.Wb = blocked.to_blocks(self.W.reshape(self.M, n, n), nb)
        K = self.ring.shape[2]
        self.ringb = np.zeros((nb, K, n * n * blocked.LANES), dtype=self.W.dtype)
        for q in range(K):
            ring_q = self.ring[:, 0, q].reshape(self.M, n, n)
            self.ringb[:, q] = blocked.to_blocks(ring_q, nb).reshape(nb, -1)
        self.hn[:, 0] = self.head[0, 0]
        self.hn[:, 1] = self.nh[0, 0]

    def _sync(self) -> None:
        """The member arrays (state, ring) from the blocks, for :meth:`state`."""
        n, K = self.n, self.ringb.shape[1]
        self.W = blocked.from_blocks(self.Wb, self.M).reshape(self.M, -1)
        for q in range(K):
            self.ring[:, 0, q] = blocked.from_blocks(
                self.ringb[:, q].reshape(self.nb, n, n, blocked.LANES), self.M
            ).reshape(self.M, -1)
        self.head[:, 0] = self.hn[:, 0].max() if self.nb else 0
        self.nh[:, 0] = self.hn[:, 1].max() if self.nb else 0

    def state(self) -> tuple[Array, Any]:
        self._sync()
        return super().state()

    def _round_trip(self) -> None:
        self._sync()
        super()._round_trip()
        self._blocks_from_members()

    def freeze(self, m: int, step: int, y: Array, status: int, message: str) -> None:
        super().freeze(m, step, y, status, message)
        b, lane = divmod(m, blocked.LANES)  # the member's lane of its block (to_blocks)
        self.Wb[b, :, :, lane] = self.W[m].reshape(self.n, self.n)

    def _advance(self, nsteps: int, save_every: int, k_final: int, out: Array) -> None:
        L = self.layout
        buf = self._rows_buffer(out)
        s = self.solver
        rec = self.rec
        sp = L.sp
        drive = blocked.drive_blocks_parallel if self.parallel else blocked.drive_blocks_serial
        args = (
            self.Wb, self.ringb, self.hn, self.coefs, self.kmax, self.coeff, float(sp[1]),
            bool(sp[2]), self.valid, self.h, int(nsteps), self.k, int(save_every),
            int(k_final), buf, float(s.rtol), float(s.atol), float(s.stall_rtol),
            float(s.divergence_factor), int(s.max_iter), rec,
        )  # fmt: skip
        self._call(lambda: drive, args, f"{L.name}, blocked ensembles")
        self._finish(out, buf, nsteps)


def with_kernel(problem: IsospectralProblem, kernel: Any) -> IsospectralProblem:
    """``problem`` with another kernel (for tests and benchmarks)."""
    return dataclasses.replace(problem, kernel=kernel)
