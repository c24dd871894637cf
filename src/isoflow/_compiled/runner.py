r"""The compiled runner: which layout and stage a run gets, and the chunks it runs.

:func:`compiled_runner` is what the time loop asks first. It returns a :class:`CompiledRunner`
when the run has a compiled path, ``None`` otherwise (the time loop then steps with the
method's own code, :class:`~isoflow._stepping.PythonRunner`). A compiled path exists for

* a problem with a kernel (:mod:`isoflow.kernels`: your ``CompiledB`` or a built-in one),
* the fixed-point solver (:class:`~isoflow.FixedPoint`, plain or Anderson-accelerated),
* a method with a compiled stage (:mod:`isoflow._compiled.stages`: IsoMP, the spherical
  midpoint, and their compositions) on a layout that provides the blocks the stage needs:
  ``so(n)``, ``u(n)``, ``su(n)``, ``Sym(n)``, ``Herm(n)`` (:mod:`.dense`; ensembles of an
  elementwise kernel as SIMD lanes, :mod:`.lanes`), :math:`(\mathbb{R}^3,\times)^N` and
  :math:`(\mathbb{R}^3,\times_L)^N` (:mod:`.particles`; point vortices, :mod:`.vortices`; spin
  chains, :mod:`.spin_chain`), the semidirect products of ``so(n)``, ``u(n)``, ``su(n)`` and
  the heavy top's :math:`\mathfrak{se}(3)` (:mod:`.pairs`); single systems and ensembles
  (units over numba threads).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._errors import IsoflowError
from .._failures import B_RAISED, MemberFailures
from .._save_grid import SaveGrid
from .._stepping import Runner
from ..kernels import CompiledB
from ..methods import Composition, Method, Strang
from ..methods import composition as _composition
from ..methods.extrapolation import interpolation_weights, start_weights
from ..methods.isomp import pack_state, state_parts
from ..nonlinear import FixedPoint
from ..problems import IsospectralProblem
from . import driver
from .dense import DenseBlas, dense_layout
from .dense_start import start_for
from .draws_ahead import StepDraws, how_to_draw, pieces
from .flat import anderson, no_mixing
from .lanes import lanes_layout
from .layout import Layout
from .pairs import PairsBlas, pair_layout
from .particles import particle_layout
from .records import Plan, SolverConstants, no_step_data
from .signatures import DriverTypes, compiled_driver, no_begin
from .spin_chain import chain_layout
from .stages import CompiledStage, StageOnLayout, StepDataRequest, stage_for
from .vortices import vortex_layout

__all__ = ["CompiledRunner", "compiled_runner", "layout_for"]

#: A unit whose state takes at least this many bytes steps in buffers the runner keeps from
#: call to call (:mod:`isoflow._compiled.driver`): fresh ones would cost a page fault per
#: 4 KiB touched. Smaller units allocate theirs in every call: they stay in the cache, and the
#: driver's loops over fresh buffers measured about 10 % faster for 10^4 so(10) members.
KEEP_BUFFERS_BYTES = 256 * 2**10

Array = NDArray[Any]


def _threads() -> int:
    import numba

    return int(numba.get_num_threads())


def layout_for(
    problem: IsospectralProblem, members: int, stage: CompiledStage, anderson: int
) -> tuple[Layout, StageOnLayout] | None:
    """The first layout that takes the run and provides the stage's blocks, with the stage's
    functions on it; ``None`` when there is none."""
    builders: list[Callable[[], Layout | None]] = [
        lambda: vortex_layout(problem, members),
        lambda: chain_layout(problem, members, _threads()),
        lambda: lanes_layout(problem, members) if anderson == 0 else None,
        lambda: dense_layout(problem, members),
        lambda: particle_layout(problem, members),
        lambda: pair_layout(problem, members),
    ]
    for build in builders:
        layout = build()
        if layout is None:
            continue
        impl = stage.on(layout)
        if impl is not None:
            return layout, impl
    return None


def compiled_runner(
    problem: IsospectralProblem, method: Method, y: Array, h: float, *,
    method_state: Any = None, k: int = 0, failures: MemberFailures | None = None,
    t0: float = 0.0,
) -> CompiledRunner | None:  # fmt: skip
    """A :class:`CompiledRunner` for the run, or ``None`` when it has no compiled path."""
    if problem.kernel is None:
        return None
    if isinstance(method, Strang) and problem.linear_part is None and not problem.forcing:
        method = method.base  # nothing to split: the base method's own stage, bit for bit
    base: Any = method
    gammas: tuple[float, ...] = (1.0,)
    if isinstance(method, Composition):
        base, gammas = method.base, tuple(method.coefficients)
    stage = stage_for(base)
    if stage is None or type(getattr(base, "solver", None)) is not FixedPoint:
        return None
    if not stage.applies(base, problem, isinstance(method, Composition)):
        return None
    alg = problem.algebra
    y = np.asarray(y)
    if y.dtype != alg.dtype:
        return None
    M = int(np.prod(alg.batch_shape(y), dtype=np.int64))
    chosen = layout_for(problem, M, stage, base.solver.anderson)
    if chosen is None:
        return None
    layout, impl = chosen
    return CompiledRunner(
        layout, impl, stage, problem, base, np.asarray(gammas, dtype=np.float64), y, h,
        method_state=method_state, k=k, failures=failures,
        composed=isinstance(method, Composition), t0=t0,
    )  # fmt: skip


class CompiledRunner(Runner):
    """Runs chunks of steps of a stage on a :class:`Layout` through the one compiled driver.

    See :class:`~isoflow._stepping.Runner` for the protocol. The units' states, the ring of
    stage offsets and the per-member records live in this object's arrays between calls.
    """

    def __init__(
        self, layout: Layout, impl: StageOnLayout, stage: CompiledStage,
        problem: IsospectralProblem, method: Any, gammas: Array, y: Array, h: float, *,
        method_state: Any = None, k: int = 0, failures: MemberFailures | None = None,
        composed: bool = False, t0: float = 0.0,
    ) -> None:  # fmt: skip
        super().__init__()
        self.t0 = float(t0)
        alg = problem.algebra
        self.composed = composed
        self.layout = layout
        self.impl = impl
        self.label = f"compiled, {layout.name}"
        if stage.name != "IsoMP":
            self.label += f", {stage.name}"
        self.core = alg.shape
        self.batch = alg.batch_shape(y)
        self.M = int(np.prod(self.batch, dtype=np.int64))
        self.U = layout.units(self.M)
        self.h = float(h)
        self.k = int(k)
        self.failures = failures if failures is not None else MemberFailures.none(self.M)
        self.kernel = problem.kernel
        self.algebra = alg
        field = layout.field or problem.kernel.field()  # type: ignore[union-attr]
        self.f: Any = field[0]
        self.fargs: tuple[Any, ...] = field[1]
        self.mp = stage.params(method, problem, layout, tuple(float(g) * float(h) for g in gammas))
        self.stage = stage
        self.method = method
        self.problem = problem
        self.solver = SolverConstants.of(method.solver)
        self.kmax = stage.offsets(method, problem)
        K = max(self.kmax, 1)
        degree = stage.start_degree(method, problem)
        self.kint = stage.start_fallback(method, problem) if self.kmax else 0
        self.coefs = np.zeros((K + (1 if self.kint else 0), K))
        for m in range(1, K + 1):
            self.coefs[m - 1, :m] = start_weights(degree, m)
        if self.kint:  # the interpolating start a fitted one falls back to (flat.guess_or_fit)
            self.coefs[K, : self.kint] = interpolation_weights(self.kint)
        self.gammas = gammas
        P = gammas.shape[0]
        self.W = layout.to_units(np.asarray(y).reshape(self.M, *self.core))
        S = self.W.shape[1]
        self.S = S
        self.member_size = int(np.prod(self.core, dtype=np.int64))
        self.ring = np.zeros((self.U, P, K, S), dtype=self.W.dtype)
        self.head = np.zeros((self.U, P), dtype=np.int64)
        self.nh = np.zeros((self.U, P), dtype=np.int64)
        self.compensated = stage.compensated(method)
        self.comp = np.zeros((self.U, P, S if self.compensated else 0), dtype=self.W.dtype)
        self._user: tuple[int, Array, Array, Array] | None = None
        if layout.restart_at_saves:  # what state() exports before the first save point
            user = np.zeros((P, K, self.M, *self.core), dtype=self.W.dtype)
            user_comp = np.zeros((P, self.M, *self.core), dtype=self.W.dtype)
            self._load_offsets(method_state, user, user_comp)
            y_user = np.array(y, copy=True).reshape(self.M, *self.core)
            self._user = (self.k, y_user, user, user_comp)
        else:
            self._load_offsets(method_state)
        self.rec = np.zeros((self.M, driver.REC_SIZE))
        self.rec[:, driver.REC_FAIL_STEP] = np.where(
            self.failures.step >= 0, self.failures.step + 1, -1
        )
        self.checkpoints_at_saves = layout.restart_at_saves  # see Layout.restart_at_saves
        self.begin = impl.begin if impl.begin is not None else no_begin
        self.mix = anderson if self.solver.anderson > 0 else no_mixing
        self.start = start_for(self.layout.record, self.W, self.kmax, self.kint)
        self.parallel = self.U >= 2 and _threads() > 1 and self._threads_allowed()
        self._drive: Any = None
        self._buffers: tuple[Array, Array, Array] | None = None
        self._step_values = 0  # values of a step's step data (all members), once drawn
        # the step data of the next chunk's first steps, drawn during this chunk's last piece:
        # (first step k0, data (n, members, D)); used only by a chunk that starts at k0
        self._drawn_next: tuple[int, Array] | None = None

    @property
    def numba_threaded(self) -> bool:
        """Members over numba threads, or a layout whose unit's work runs on them."""
        return self.parallel or self.layout.threaded

    @property
    def serial_by_default(self) -> bool:
        """One system's threaded work on one thread unless the run asks for more."""
        return self.layout.serial_by_default and not self.parallel

    def _threads_allowed(self) -> bool:
        """Units may run on numba threads unless they call a multithreaded BLAS (the BLAS
        threads in force: those of the run's thread plan, :mod:`isoflow.threads`)."""
        if not isinstance(self.layout.record, (DenseBlas, PairsBlas)):
            return True
        from ..threads import blas_threads

        return blas_threads() <= 1

    # ---- method state <-> ring ---------------------------------------------------------------
    def _position_states(self, state: Any) -> list[Any]:
        """The base method's state of every substep position (one, unless composed)."""
        P = self.gammas.shape[0]
        return _composition._unpack(state, P) if self.composed else [state]

    def _load_offsets(
        self, state: Any, user: Array | None = None, user_comp: Array | None = None
    ) -> None:
        """The ring and the compensation from the method state (user's layout); with
        ``user`` (``(P, K, M, *core)``) and ``user_comp`` (``(P, M, *core)``), the given
        values are also kept there."""
        for p, st in enumerate(self._position_states(state)):
            hp = float(self.gammas[p]) * self.h
            offsets, E = state_parts(st, hp)
            if self.compensated and E is not None:
                Em = np.asarray(E).reshape(self.M, *self.core)
                self.comp[:, p] = self.layout.to_units(Em)
                if user_comp is not None:
                    user_comp[p] = Em
            if self.kmax == 0 or not offsets:
                continue
            offsets = offsets[: self.kmax]
            nh = len(offsets)
            for q, D in enumerate(offsets):  # newest first
                Dm = np.asarray(D).reshape(self.M, *self.core)
                self.ring[:, p, (nh - 1 - q)] = self.layout.to_units(Dm)
                if user is not None:
                    user[p, nh - 1 - q] = Dm
            self.head[:, p] = nh - 1
            self.nh[:, p] = nh

    def _export_offsets(self) -> Any:
        if self.kmax == 0 and not self.compensated:
            return None
        L = self.layout.lanes
        alive_units = np.zeros(self.U, dtype=bool)
        alive_units[np.flatnonzero(self.failures.alive) // L] = True
        K = self.ring.shape[2]
        units = np.arange(self.U)
        user = self._user if self._user is not None and self._user[0] == self.k else None
        states: list[Any] = []
        for p in range(self.gammas.shape[0]):
            nh_p = self.nh[alive_units, p] if alive_units.any() else self.nh[:, p]
            nh = int(nh_p.max()) if self.kmax else 0
            out: list[Any] = []
            for q in range(nh):
                slots = (self.head[:, p] - q) % K
                if user is not None:
                    D = user[2][p, slots[np.arange(self.M) // L], np.arange(self.M)]
                else:
                    D = np.array(
                        self.layout.offsets_from_units(self.ring[units, p, slots]), copy=True
                    )
                out.append(D[0] if self.batch == () else D)  # members flattened, as PythonRunner
            E = None
            if self.compensated:
                if user is not None:
                    E = user[3][p].copy()
                else:
                    E = np.array(self.layout.from_units(self.comp[:, p]), copy=True)
                E = E[0] if self.batch == () else E
            states.append(pack_state(float(self.gammas[p]) * self.h, tuple(out), E))
        return _composition._pack(states) if self.composed else states[0]

    def state(self) -> tuple[Array, Any]:
        if self._user is not None and self._user[0] == self.k:
            y = self._user[1].copy()
        else:
            y = np.array(self.layout.from_units(self.W), copy=True)
        return y.reshape(*self.batch, *self.core), self._export_offsets()

    def B_at(self, rows: Array) -> Array:
        return self.kernel.evaluate(rows, self.algebra)  # type: ignore[union-attr]

    def freeze(self, m: int, step: int, y: Array, status: int, message: str) -> None:
        y = np.asarray(y).reshape(1, *self.core)
        if self.layout.lanes == 1:
            self.W[m] = self.layout.to_units(y)[0]
        else:  # the member's lane of its unit (the lanes' map is a permutation: exact)
            members = np.array(self.layout.from_units(self.W), copy=True)
            members[m] = y[0]
            self.W[...] = self.layout.to_units(members)
        if self._user is not None:
            self._user[1][m] = y[0]
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
    def _driver(self, args: tuple[Any, ...], parallel: bool | None = None) -> Any:
        """The compiled driver of this run (by default with the run's ``parallel``): the stage
        compiled for the run's types and the driver for its signature (compiled, or loaded
        from numba's cache, once per process and signature:
        :func:`~isoflow._compiled.signatures.compiled_driver`)."""
        impl = self.impl
        dt = DriverTypes(
            self.f, self.fargs, self.layout.record, self.mp, self.W.dtype, len(self.core)
        )
        dt.compile_stage(self.begin, impl.iterate, impl.finish, self.mix, self.start)
        par = self.parallel if parallel is None else parallel
        return compiled_driver(dt.driver_signature(args), par, units=args[3].shape[0])

    def advance(self, nsteps: int, grid: SaveGrid, out: Array) -> None:
        if not self.layout.restart_at_saves:
            self._advance(nsteps, grid, out)
            return
        row = 0
        left = nsteps
        while left > 0 and self.failures.alive.any():
            k0 = self.k
            piece = min(left, max(grid.next_after(k0) - k0, 1))
            r = 1 if grid.is_save(k0 + piece) else 0
            self._advance(piece, grid, out[row : row + r])
            row += r
            left -= piece
            if r:
                self._round_trip()

    def _round_trip(self) -> None:
        """Map the state and the offsets to the user's layout and back (at a save point);
        the user-layout values are kept: they are what :meth:`state` exports here, so that a
        restart from them maps them forward to exactly this runner's arrays."""
        L = self.layout
        y = np.array(L.from_units(self.W), copy=True)
        self.W = np.ascontiguousarray(L.to_units(y))
        P, K = self.ring.shape[1], self.ring.shape[2]
        user = np.empty((P, K, *y.shape), dtype=y.dtype)
        user_comp = np.zeros((P, *y.shape), dtype=y.dtype)
        for p in range(P):
            for q in range(K):
                user[p, q] = L.offsets_from_units(self.ring[:, p, q])
                self.ring[:, p, q] = L.to_units(user[p, q])
            if self.compensated:
                user_comp[p] = L.from_units(self.comp[:, p])
                self.comp[:, p] = L.to_units(user_comp[p])
        self._user = (self.k, y, user, user_comp)

    def _rows_buffer(self, out: Array) -> Array:
        """Where the driver writes the saved rows: ``out`` itself when a unit is a member in
        the user's layout and ``out`` is contiguous, else a flat buffer (see :meth:`_finish`).
        Also clears the per-call counters of the member records."""
        R = out.shape[0]
        rec = self.rec
        rec[:, driver.REC_ITERATIONS] = 0.0
        rec[:, driver.REC_ITERATIONS_MAX] = 0.0
        rec[:, driver.REC_RESIDUAL_MAX] = 0.0
        rec[:, driver.REC_CALL_DONE] = 0.0
        if self.layout.identity and out.flags.c_contiguous:
            return out.reshape(R, self.M, self.S)
        return np.empty((R, self.M, self.member_size), self.W.dtype)

    def _head(self) -> tuple[Any, ...]:
        """The driver's first arguments: the stage's functions, the mixing and the field."""
        return (
            self.begin, self.impl.iterate, self.impl.finish, self.mix, self.start, self.f,
            self.fargs,
        )  # fmt: skip

    def _call(self, args: tuple[Any, ...]) -> None:
        """Run the compiled driver on ``args``; the first call gets it from :meth:`_driver`
        and compiles it (or loads it from numba's cache; a compilation is announced), later
        calls reuse it. A parallel driver hands its units to the threads as they come free
        (:func:`~isoflow._compiled.driver.drive_parallel`)."""
        head = self._head()
        if self._drive is None:
            from .._compile_clock import compile_notice

            what = f"{self.layout.name} with {getattr(self.f, '__name__', 'B')}"
            with compile_notice(f"the compiled loop for {what}"):
                drive = self._driver(args)
                self._drive = drive  # compiled: a raise from here on is the field's
                drive(*head, *args)
            self._drive = drive
        else:
            self._drive(*head, *args)

    def _args(
        self, units: slice, nsteps: int, k0: int, grid: SaveGrid, rows: Array,
        data: Array | None = None,
    ) -> tuple:  # fmt: skip
        """The driver's arguments (after the functions) for the ``units`` (views of this
        runner's arrays) and ``nsteps`` steps from step ``k0``, saved rows into ``rows``; the
        step data is drawn here unless it is given."""
        L = self.layout.lanes
        members = slice(
            None if units.start is None else units.start * L,
            None if units.stop is None else units.stop * L,
        )
        plan = Plan.of(
            self.h, nsteps, k0, grid, self.kmax, self.impl.begin is not None,
            self.impl.begin_moves_state, self.kint,
        )  # fmt: skip
        if data is None:
            data = self._step_data(k0, nsteps, members)
        return (
            self.layout.record, self.mp, self.impl.nwork, self.W[units], self.ring[units],
            self.head[units], self.nh[units], self.comp[units], self.coefs, self.gammas, plan,
            data, rows,
            self.solver, self.rec[members], *self._thread_buffers(),
        )  # fmt: skip

    def _thread_buffers(self) -> tuple[Array, Array, Array]:
        """The driver's state-sized buffers, one set per numba thread of a parallel call
        (:mod:`isoflow._compiled.driver`): ``(T, 5, S)``, ``(T, max(nwork, 1), S)`` and the
        compensations ``(T, P, S)`` (``S = 0`` without compensation). Kept from call to call
        (fresh memory costs a page fault per 4 KiB touched); grown when a call may run on more
        threads than the buffers cover. Units below :data:`KEEP_BUFFERS_BYTES` get buffers
        with ``S = 0``: the driver then allocates its own in every call."""
        import numba

        T = max(int(numba.get_num_threads()), 1) if self.parallel else 1
        if self._buffers is None or self._buffers[0].shape[0] < T:
            dt = self.W.dtype
            S = self.S if self.S * dt.itemsize >= KEEP_BUFFERS_BYTES else 0
            P = self.gammas.shape[0]
            self._buffers = (
                np.empty((T, 5, S), dtype=dt),
                np.empty((T, max(self.impl.nwork, 1), S), dtype=dt),
                np.empty((T, P, self.comp.shape[2] if S else 0), dtype=dt),
            )
        return self._buffers

    def _step_data(self, k0: int, nsteps: int, members: slice) -> Array:
        """The stage's step data of the steps ``k0 + 1 ..`` for the units' ``members`` (their
        lanes; padding lanes are member ``-1``), or none."""
        idx = np.arange(self.U * self.layout.lanes)[members]
        if self.stage.step_data is None:
            return no_step_data(nsteps, idx.size)
        idx = np.where(idx < self.M, idx, -1)
        request = StepDataRequest(int(k0), int(nsteps), idx, self.h, self.t0)
        data = np.ascontiguousarray(
            self.stage.step_data(self.method, self.problem, request), dtype=np.float64
        )
        if data.ndim != 3 or data.shape[:2] != (nsteps, idx.size):
            raise IsoflowError(
                f"the step data of {self.stage.name} has shape {data.shape}, not "
                f"({nsteps}, {idx.size}, D)"
            )
        if members == slice(None):  # not a member redone alone (:meth:`_isolate`)
            self._step_values = data.shape[1] * data.shape[2]
        return data

    def _how_to_draw(self, nsteps: int) -> str:
        """How this chunk draws its step data (:func:`~isoflow._compiled.draws_ahead.
        how_to_draw`)."""
        from ..threads import blas_threads

        return how_to_draw(
            nsteps=nsteps, values_per_step=self._step_values,
            serial_loop=not self.parallel and not self.layout.threaded,
            numba_threads=self._draw_threads(), blas_threads=blas_threads(),
        )  # fmt: skip

    def _draw_threads(self) -> int:
        """Threads that may draw step data, the caller's included: the numba threads but
        those the run keeps busy beside the loop (:attr:`threads_beside`)."""
        return _threads() - self.threads_beside

    def _start_draws(self, pool: Any, k0: int, nsteps: int) -> StepDraws:
        """The step data of the steps ``k0 + 1 .. k0 + nsteps`` (all members), every thread
        of ``pool`` (:meth:`_draw_pool`) drawing it from now on (:class:`~isoflow._compiled.
        draws_ahead.StepDraws`; its ``result()`` draws the rest on this thread)."""
        everyone = slice(None)
        draws = StepDraws(lambda k, n: self._step_data(k, n, everyone), k0, nsteps)
        for _ in range(self._draw_threads() - 1):
            pool.submit(draws.help)
        return draws

    def _draw_pool(self) -> Any:
        """The helper threads that draw beside the caller (:meth:`_draw_threads` less one),
        for one chunk (a pool kept across chunks would not survive a ``fork`` of the
        process)."""
        from concurrent.futures import ThreadPoolExecutor

        return ThreadPoolExecutor(self._draw_threads() - 1, thread_name_prefix="isoflow-draws")

    def _call_in_pieces(self, nsteps: int, grid: SaveGrid, buf: Array) -> None:
        """The chunk's steps in :func:`~isoflow._compiled.draws_ahead.pieces`, each piece's
        step data drawn by helper threads while the loop runs the piece before (and by this
        thread too once the loop is done: :class:`~isoflow._compiled.draws_ahead.StepDraws`).

        While the last piece runs, the helpers draw the first steps of the run's next chunk
        (as many as :func:`~isoflow._compiled.draws_ahead.pieces` gives this chunk first, not
        past the run's last step), which that chunk then takes as its first piece: otherwise
        a helper would wait for the end of the chunk, and the next chunk would begin with
        draws that nothing runs beside (a run's chunks last about half a second,
        :class:`isoflow._time_loop.ChunkPolicy`, shorter where the writer takes few rows a
        chunk). The data of a step depends on the step and the member alone, so who draws it,
        and when, changes nothing."""
        everyone = slice(None)
        k0 = self.k
        sizes = pieces(nsteps)
        next_steps = min(sizes[0], grid.k_final - (k0 + nsteps))  # drawn for the next chunk
        first, self._drawn_next = self._drawn_next, None
        if first is not None and (first[0] != k0 or first[1].shape[0] > nsteps):
            first = None  # drawn for another chunk (not the one that follows)
        if first is not None:
            m = first[1].shape[0]
            sizes = [m, *pieces(nsteps - m)] if m < nsteps else [m]
        row = 0
        try:
            with self._draw_pool() as pool:
                if first is not None:
                    data = first[1]
                else:
                    data = self._start_draws(pool, k0, sizes[0]).result()
                ahead: StepDraws | None = None
                try:
                    for j, n in enumerate(sizes):
                        ahead = None
                        if j + 1 < len(sizes):
                            ahead = self._start_draws(pool, k0 + n, sizes[j + 1])
                        elif next_steps > 0:  # the next chunk's first piece
                            ahead = self._start_draws(pool, k0 + n, next_steps)
                        r = grid.count(k0, k0 + n)
                        self.rec[:, driver.REC_CALL_DONE] = 0.0
                        self._call(self._args(everyone, n, k0, grid, buf[row : row + r], data))
                        k0 += n
                        row += r
                        if ahead is not None:
                            data = ahead.result()
                    if next_steps > 0:
                        self._drawn_next = (k0, data)
                except BaseException:
                    if ahead is not None:
                        ahead.cancel()  # the helpers stop before the pool is shut down
                    raise
        except Exception:
            # no member finished the chunk: :meth:`_advance` redoes them all from its start
            # when their field may raise (as after a raise in an undivided chunk)
            self.rec[:, driver.REC_CALL_DONE] = 0.0
            raise

    def _advance(self, nsteps: int, grid: SaveGrid, out: Array) -> None:
        buf = self._rows_buffer(out)
        everyone = slice(None)
        before = self._arrays(everyone) if self.may_raise else None
        raised: Exception | None = None
        try:
            how = self._how_to_draw(nsteps)
            if how == "ahead":
                self._call_in_pieces(nsteps, grid, buf)
            else:
                data = None
                if how == "together":
                    with self._draw_pool() as pool:
                        draws = self._start_draws(pool, self.k, nsteps)
                        data = draws.result()
                self._call(self._args(everyone, nsteps, self.k, grid, buf, data))
        except Exception as exc:  # the field raised (a parallel driver says SystemError)
            if before is None or self._drive is None:
                raise
            raised = exc
        undone = np.flatnonzero(self.rec[:, driver.REC_CALL_DONE] == 0.0)
        if undone.size and before is not None:  # their field raised: redo them, alone
            for m in undone:
                self._set_arrays(slice(m, m + 1), tuple(a[m : m + 1] for a in before))
            self._isolate(undone, nsteps, grid, buf)
        elif undone.size or raised is not None:
            why = (
                "; a field declared raises=False raised on a numba thread, which drops its "
                "exception: run with raises=True (the default) or on one thread to see it"
                if before is None and raised is not None and self._drive is not None
                else ""
            )
            raise IsoflowError(
                f"the compiled loop stopped {undone.size} member(s) in the middle of a chunk "
                f"without a result ({raised!r}); the run cannot go on{why}"
            ) from raised
        if out.shape[0] and not np.may_share_memory(out, buf):
            out[...] = self.layout.rows_from_flat(buf)
        self._absorb(nsteps)

    # ---- a field that raises: only the members whose B raises fail ---------------------------
    @property
    def may_raise(self) -> bool:
        """Whether the field is the user's (:class:`~isoflow.CompiledB`), which may raise: a
        chunk then keeps a copy of the arrays it changes, to redo the members after a raise.
        (Such a run has one member per unit: only built-in kernels run as lanes.)"""
        return isinstance(self.kernel, CompiledB) and self.kernel.raises and self.layout.lanes == 1

    @property
    def _changed(self) -> tuple[Array, ...]:
        """The arrays a call changes."""
        return (self.W, self.ring, self.head, self.nh, self.comp, self.rec)

    def _arrays(self, units: slice) -> tuple[Array, ...]:
        """Copies of what a call changes for the ``units`` (members: one per unit)."""
        return tuple(a[units].copy() for a in self._changed)

    def _set_arrays(self, units: slice, saved: tuple[Array, ...]) -> None:
        for a, b in zip(self._changed, saved, strict=True):
            a[units] = b

    def _isolate(self, members: NDArray[np.intp], nsteps: int, grid: SaveGrid, buf: Array) -> None:
        """Redo the chunk of the ``members`` whose call did not return, one by one (serially,
        each from its state before the call: the members' steps are independent, so every
        result equals a run without the raising members, bit for bit); a member whose ``B``
        raises is redone step by step and frozen at its last good state with
        :data:`B_RAISED` at the step that raised."""
        rows = np.empty((buf.shape[0], 1, buf.shape[2]), dtype=self.W.dtype)
        drive = self._driver(self._args(slice(0, 1), nsteps, self.k, grid, rows), False)
        for m in members:
            one = slice(m, m + 1)
            saved = self._arrays(one)
            try:
                drive(*self._head(), *self._args(one, nsteps, self.k, grid, rows))
            except Exception:
                self._set_arrays(one, saved)
                self._step_until_raise(m, drive, nsteps, grid, buf)
            else:
                buf[:, m] = rows[:, 0]

    def _step_until_raise(
        self, m: int, drive: Any, nsteps: int, grid: SaveGrid, buf: Array
    ) -> None:
        """Member ``m``'s chunk one step per call until its field raises (see
        :meth:`_isolate`); its remaining rows repeat its last good state."""
        one = slice(m, m + 1)
        row = 0
        for k0 in range(self.k, self.k + nsteps):
            saves = 1 if grid.is_save(k0 + 1) else 0
            rows = np.empty((saves, 1, buf.shape[2]), dtype=self.W.dtype)
            saved = self._arrays(one)
            try:
                drive(*self._head(), *self._args(one, 1, k0, grid, rows))
            except Exception as exc:
                self._set_arrays(one, saved)
                self._fail_raised(m, k0, exc)
                buf[row:, m] = self.W[m]
                return
            buf[row : row + saves, m] = rows[:, 0]
            row += saves

    def _fail_raised(self, m: int, k0: int, exc: Exception) -> None:
        """Record that member ``m``'s field raised ``exc`` in the step from step ``k0``."""
        self._mark_failed(m, k0, B_RAISED)
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
