r"""Thread policy: how many BLAS/OpenMP and numba threads a solve runs, and where they apply.

isoflow runs two kinds of parallel code. BLAS/OpenMP libraries do NumPy's matrix products and
the products of the compiled dense loops (above ``n = 16`` the compiled loop calls numba's
``np.dot``, which binds SciPy's cython BLAS: a *second* OpenBLAS, ``libscipy_openblas``, besides
NumPy's). numba threads run isoflow's own compiled loops over ensemble members, blocks of
members and chunks of long spin chains. Each library defaults to one thread per core; nesting
them (a numba thread calling a multithreaded BLAS) or running both pools at once oversubscribes
the machine, and an OpenBLAS thread that waits for a core held by another process stalls every
product it takes part in (on two cores with the other one busy, the README's first solve took
281 s with two BLAS threads against 4.7 s with one). So:

* every solve settles its thread counts (a :class:`ThreadPlan`) before it starts and applies
  them *inside its time loop*, to every BLAS and OpenMP library loaded, again whenever the run
  loads another one (a chunk that imported a module is followed by a new look at the loaded
  libraries), and restores the previous limits when it ends;
* the default (``threads=None``): one BLAS/OpenMP thread (:data:`DEFAULT_BLAS_THREADS`; the
  measurements are in ``docs/user_guide/threads.rst``: two BLAS threads lose to one for the
  sizes measured as soon as the other core is busy, and gain nothing for small states even on
  an idle machine), and numba threads on every core for the compiled loops that run members in
  parallel (members are independent: each thread takes the next member as it comes free, so
  a thread slowed by another process leaves the rest to the others);
* ``threads=k`` (:func:`isoflow.solve`, :func:`isoflow.io.resume`, ``isoflow run --threads``):
  the solve may use ``k`` cores: numba threads when its compiled loop runs members (or chunks,
  or the pieces of one large complex matrix) in parallel, else BLAS threads;
  ``threads={"blas": b, "numba": m}`` chooses both. A large complex matrix runs its pieces on
  one thread unless the run asks for more (:func:`default_request`; its pieces are split in
  equal shares, so a thread sharing its core with another process holds up every pass);
* inside ``with thread_limits(...)``, solves without ``threads=`` use the block's choice;
* ``blas * numba <= cores`` always: a request for more threads than cores is refused; and the
  environment variables a user sets are upper bounds: ``OPENBLAS_NUM_THREADS``,
  ``MKL_NUM_THREADS`` and ``OMP_NUM_THREADS`` for BLAS/OpenMP, ``NUMBA_NUM_THREADS`` for
  numba (which, as numba documents, is independent of ``OMP_NUM_THREADS``);
* compiled members that call BLAS (the dense BLAS stage on an ensemble) run over numba threads
  only with one BLAS thread;
* a single system with noise whose compiled loop runs on one core draws the increments of a
  chunk's next piece on the other numba threads while the loop runs, and an ensemble draws a
  chunk's increments on all of them before its loop, when the plan gives numba at least two
  threads and BLAS one (:mod:`isoflow._compiled.draws_ahead`; the states do not change).

The counts a run used are in ``SolveStats.threads`` (:class:`isoflow.SolveStats`) and in its
result file.

Examples
--------
>>> import isoflow as iso
>>> with iso.threads.thread_limits(blas=1) as limits:     # numba gets all cores, BLAS one
...     limits["blas"]
1
"""

from __future__ import annotations

import numbers
import os
import sys
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from typing import Any

from ._errors import ParameterError

__all__ = [
    "BLAS_ENVIRONMENT",
    "DEFAULT_BLAS_THREADS",
    "NUMBA_ENVIRONMENT",
    "ThreadPlan",
    "ThreadRequest",
    "available_cores",
    "current_threads",
    "default_request",
    "environment_limits",
    "plan_threads",
    "thread_limits",
]

#: What a solve may be asked to run with: ``None`` (the default policy, or the enclosing
#: :func:`thread_limits` block's choice), a number of cores, or ``{"blas": b, "numba": m}``.
ThreadRequest = int | Mapping[str, int] | None

#: BLAS/OpenMP threads of a solve by default (measured: ``docs/user_guide/threads.rst``).
DEFAULT_BLAS_THREADS = 1
#: Environment variables that bound the BLAS/OpenMP threads (the smallest one set counts).
BLAS_ENVIRONMENT = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OMP_NUM_THREADS")
#: Environment variables that bound the numba threads (numba's own; like numba, isoflow does
#: not read ``OMP_NUM_THREADS`` for them).
NUMBA_ENVIRONMENT = ("NUMBA_NUM_THREADS",)

#: The request of the innermost :func:`thread_limits` block (solves without ``threads=``).
_REQUEST: ContextVar[ThreadRequest] = ContextVar("isoflow_thread_request", default=None)
#: The plan in force (set while a block or a solve applies one).
_ACTIVE: ContextVar[ThreadPlan | None] = ContextVar("isoflow_thread_plan", default=None)


@dataclass(frozen=True)
class ThreadPlan:
    """Thread counts of a solve or a :func:`thread_limits` block.

    Attributes
    ----------
    blas : int
        Threads of every BLAS and OpenMP library.
    numba : int
        numba threads.
    cores : int
        Cores the process may run on.
    """

    blas: int
    numba: int
    cores: int

    def as_dict(self) -> dict[str, int]:
        """``{"cores", "numba", "blas"}`` (as :func:`current_threads`)."""
        return {"cores": self.cores, "numba": self.numba, "blas": self.blas}


def available_cores() -> int:
    """Cores this process may run on (``os.sched_getaffinity`` where available)."""
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except AttributeError:  # pragma: no cover - not on Linux
        return max(os.cpu_count() or 1, 1)


def current_threads() -> dict[str, int]:
    """Current thread counts: ``{"cores", "numba", "blas"}`` (``blas`` the largest pool)."""
    import numba
    from threadpoolctl import threadpool_info

    blas = [p["num_threads"] for p in threadpool_info() if p.get("user_api") == "blas"]
    return {
        "cores": available_cores(),
        "numba": int(numba.get_num_threads()),
        "blas": max(blas) if blas else 1,
    }


def _environment_count(name: str) -> int | None:
    """The thread count the environment variable ``name`` sets (``None``: unset or empty)."""
    text = os.environ.get(name, "").strip()
    if not text:
        return None
    first = text.split(",")[0].strip()  # OMP_NUM_THREADS may list one count per nesting level
    if not first.isdigit() or int(first) < 1:
        raise ParameterError(
            f"{name}={text!r} is not a positive thread count; set it to an integer >= 1 or unset it"
        )
    return int(first)


def check_numba_environment() -> None:
    """Refuse a malformed :data:`NUMBA_ENVIRONMENT` variable by name before numba is imported
    (numba itself fails its import with "Number of threads specified must be > 0")."""
    for name in NUMBA_ENVIRONMENT:
        _environment_count(name)


def environment_limits() -> dict[str, int | None]:
    """Upper bounds on the thread counts from the environment: ``{"blas", "numba"}``.

    Each is the smallest of :data:`BLAS_ENVIRONMENT` (resp. :data:`NUMBA_ENVIRONMENT`) that is
    set, or ``None``.

    Raises
    ------
    ParameterError
        A variable is set to something other than a positive integer.
    """

    def bound(names: tuple[str, ...]) -> int | None:
        counts = [c for c in map(_environment_count, names) if c is not None]
        return min(counts) if counts else None

    return {"blas": bound(BLAS_ENVIRONMENT), "numba": bound(NUMBA_ENVIRONMENT)}


def _count(value: Any, what: str) -> int:
    """``value`` as a thread count (a positive integer), else :class:`ParameterError`."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 1:
        raise ParameterError(f"{what} must be a positive integer, got {value!r}")
    return int(value)


def _requested(request: ThreadRequest, cores: int, parallel: bool) -> tuple[int, int]:
    """``(blas, numba)`` asked for by ``request`` (before the environment's bounds)."""
    if request is None:
        return DEFAULT_BLAS_THREADS, cores
    if isinstance(request, Mapping):
        unknown = sorted(map(str, set(request) - {"blas", "numba"}))
        if unknown:
            raise ParameterError(
                f"threads: unknown key(s) {', '.join(unknown)}; give 'blas' and/or 'numba'"
            )
        blas = None if request.get("blas") is None else _count(request["blas"], "threads['blas']")
        numba = (
            None if request.get("numba") is None else _count(request["numba"], "threads['numba']")
        )
        if blas is None and numba is None:
            return DEFAULT_BLAS_THREADS, cores
        if blas is None:
            assert numba is not None
            blas = max(cores // numba, 1)
        if numba is None:
            numba = max(cores // blas, 1)
        if blas * numba > cores:
            raise ParameterError(
                f"threads: blas * numba = {blas} * {numba} exceeds the {cores} available "
                "core(s); nested pools would oversubscribe them"
            )
        return blas, numba
    if isinstance(request, bool) or not isinstance(request, numbers.Integral):
        raise ParameterError(
            f"threads must be None, a number of cores or {{'blas': b, 'numba': m}}, got {request!r}"
        )
    k = _count(request, "threads")
    if k > cores:
        raise ParameterError(
            f"threads = {k} exceeds the {cores} core(s) this process may run on; give at most "
            f"{cores}"
        )
    return (1, k) if parallel else (k, 1)


def plan_threads(threads: ThreadRequest = None, *, parallel: bool = True) -> ThreadPlan:
    """The thread counts a solve runs with (see the module docstring).

    Parameters
    ----------
    threads : None, int or mapping
        ``None``: the enclosing :func:`thread_limits` block's choice, else the default policy
        (:data:`DEFAULT_BLAS_THREADS` BLAS threads, numba threads on every core); ``k``: ``k``
        cores, as numba threads when ``parallel`` else as BLAS threads;
        ``{"blas": b, "numba": m}``: both (a missing one gets the cores the other leaves).
    parallel : bool
        Whether the run's compiled loop spreads its work over numba threads.

    Returns
    -------
    ThreadPlan
        The counts, bounded by the environment (:func:`environment_limits`) and by numba's
        pool (``NUMBA_NUM_THREADS``).

    Raises
    ------
    ParameterError
        A malformed request, more threads than cores (``blas * numba > cores``), or a
        malformed environment variable.
    """
    import numba as nb

    cores = available_cores()
    request = _REQUEST.get() if threads is None else threads
    blas, numba = _requested(request, cores, parallel)
    env = environment_limits()
    if env["blas"] is not None:
        blas = min(blas, env["blas"])
    if env["numba"] is not None:
        numba = min(numba, env["numba"])
    numba = min(numba, int(nb.config.NUMBA_NUM_THREADS))  # type: ignore[attr-defined]
    return ThreadPlan(blas=blas, numba=numba, cores=cores)


def default_request(threads: ThreadRequest = None) -> bool:
    """Whether a solve given ``threads`` runs with the default policy: no request of its own
    and none from an enclosing :func:`thread_limits` block."""
    return threads is None and _REQUEST.get() is None


def blas_threads() -> int:
    """BLAS threads in force: the applied plan's, else the largest loaded pool's."""
    plan = _ACTIVE.get()
    return plan.blas if plan is not None else current_threads()["blas"]


def _load_blas() -> None:
    """Load the BLAS libraries isoflow's loops use, so that limits set now reach them:
    NumPy's, and SciPy's (numba's ``np.dot`` binds ``scipy.linalg.cython_blas``)."""
    import numpy  # noqa: F401

    try:
        import scipy.linalg.cython_blas  # noqa: F401
    except ImportError:  # pragma: no cover - scipy is a dependency
        pass


#: threadpoolctl's controller of the loaded libraries, with the number of imported modules when
#: it looked (finding the libraries costs about 2 ms; limiting them through it 0.05 ms).
_CONTROLLER: tuple[int, Any] | None = None


def _controller() -> Any:
    """threadpoolctl's controller of the loaded libraries, looked for again after imports."""
    global _CONTROLLER
    cached = _CONTROLLER
    if cached is None or cached[0] != len(sys.modules):
        from threadpoolctl import ThreadpoolController

        controller = ThreadpoolController()
        cached = _CONTROLLER = (len(sys.modules), controller)
    return cached[1]


class ThreadPools:
    """Applies a :class:`ThreadPlan` to numba and to every loaded BLAS/OpenMP library, and
    restores what was there before.

    The limits reach the libraries loaded when :meth:`apply` runs; :meth:`refresh` (cheap:
    it compares the number of imported modules and the libraries' thread counts, about
    10 us) applies them again after an import loaded more, or after something else changed
    them (another thread's solve restoring its own limits), so a library loaded or reset in
    the middle of a run is limited from the next chunk on.
    """

    def __init__(self) -> None:
        self.plan: ThreadPlan | None = None
        self._limiter: Any = None
        self._modules = -1
        self._counts: list[int] = []
        self._numba_before: int | None = None
        self._token: Any = None

    def apply(self, plan: ThreadPlan) -> None:
        """Make ``plan`` the counts in force (numba first: it may load its threading layer;
        NumPy's and SciPy's BLAS are loaded before the first limits, so that a library the
        run loads later, such as SciPy's that numba's ``np.dot`` binds, starts limited)."""
        import numba as nb

        if self.plan is None:
            _load_blas()

        if self._numba_before is None:
            self._numba_before = int(nb.get_num_threads())
        nb.set_num_threads(plan.numba)
        if self._token is None:
            self._token = _ACTIVE.set(plan)
        else:
            _ACTIVE.set(plan)
        changed = self.plan is None or plan.blas != self.plan.blas
        self.plan = plan
        if changed:
            self._limit()
        else:
            self.refresh()

    def refresh(self) -> None:
        """Apply the limits again if modules were imported (and libraries maybe loaded) or
        the libraries' thread counts are no longer those set."""
        if len(sys.modules) != self._modules or self._thread_counts() != self._counts:
            self._limit()

    @staticmethod
    def _thread_counts() -> list[int]:
        return [int(lib.num_threads) for lib in _controller().lib_controllers]

    def _limit(self) -> None:
        assert self.plan is not None
        if self._limiter is not None:
            self._limiter.restore_original_limits()
        controller = _controller()
        self._modules = len(sys.modules)
        self._limiter = controller.limit(limits=self.plan.blas)  # every BLAS and OpenMP
        self._counts = self._thread_counts()  # what the libraries took (a build may cap it)

    def restore(self) -> None:
        """Put back the limits and the numba threads from before the first :meth:`apply`."""
        import numba as nb

        if self._limiter is not None:
            self._limiter.restore_original_limits()
            self._limiter = None
        if self._numba_before is not None:
            nb.set_num_threads(self._numba_before)
            self._numba_before = None
        if self._token is not None:
            _ACTIVE.reset(self._token)
            self._token = None
        self.plan = None


@contextmanager
def thread_limits(
    blas: int | None = None, numba: int | None = None, *, threads: int | None = None
) -> Iterator[dict[str, int]]:
    """Limit BLAS/OpenMP and numba threads inside a ``with`` block, so that
    ``blas * numba <= cores``; solves in the block without ``threads=`` use the same request.

    Parameters
    ----------
    blas, numba : int or None
        Requested threads. ``None`` for one of them gives it what the other leaves
        (``cores // other``); both ``None``: the default policy (:func:`plan_threads`).
    threads : int or None
        Instead of ``blas`` and ``numba``: the cores each solve in the block may use (numba
        threads for a loop that runs members in parallel, else BLAS threads); outside solves,
        numba gets them and BLAS one thread.

    Yields
    ------
    dict
        The limits in force, ``{"cores", "numba", "blas"}`` (bounded by the environment, see
        :func:`environment_limits`).

    Raises
    ------
    ParameterError
        A request below 1, a combination exceeding the cores, or ``threads`` together with
        ``blas`` or ``numba``.

    Notes
    -----
    NumPy's and SciPy's BLAS are loaded first, so the limits reach both; a solve in the block
    applies them again to any library loaded during its run.
    """
    request: ThreadRequest
    if threads is not None:
        if blas is not None or numba is not None:
            raise ParameterError("thread_limits: give threads, or blas and/or numba, not both")
        request = threads
    else:
        request = {k: v for k, v in (("blas", blas), ("numba", numba)) if v is not None}
    plan = plan_threads(request, parallel=True)
    pools = ThreadPools()  # its first apply loads NumPy's and SciPy's BLAS
    token = _REQUEST.set(request)
    try:
        pools.apply(plan)
        yield plan.as_dict()
    finally:
        pools.restore()
        _REQUEST.reset(token)
