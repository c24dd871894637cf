"""Continuing a streamed run from its last checkpoint: :func:`resume`.

The order is: take the file's write lock (a live writer gets a clear error); open and validate
the file; check sizes before building anything; build the problem and method from the stored
configuration (:func:`~isoflow.io.rebuild.rebuild_run`, for a model of your own the one you
name again) or take them as arguments; check them against the file (model, time grid, shape,
method); validate the restart as :func:`isoflow.solve` validates a start
(:func:`isoflow._solve.check_restart`: checked, not projected, so that the run continues from
exactly the state it held); verify every row's checksum; compare the model with the
fingerprint the file recorded when the run started (:mod:`isoflow._fingerprint`: a changed
model is refused with :class:`~isoflow.ModelChangedError` unless ``force``); and only then
touch the file (rewrite a killed or version 1 file, truncate it to the checkpoint) and continue
through the time loop's own entry (:func:`isoflow._solve.continue_run`). A refusal at any step
leaves the file unchanged.

The per-step arithmetic, the method state (e.g. IsoMP's warm start) and the step ranges between
saves are those of the uninterrupted run, so the final state equals an uninterrupted run's bit
for bit.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .._errors import ModelChangedError, ParameterError, ResultFileError
from .._failures import MemberFailures
from .._fingerprint import fingerprint_changes, model_fingerprint
from .._flags import check_flag
from .._method_settings import method_settings, settings_changes
from .._solution import RUN_FINISHED, SolveStats
from .._solve import RunState, Solution, check_continue_options, check_restart, continue_run
from .._time_loop import failure_fields
from ..diagnostics import DiagnosticsAccumulator, series_names
from ..methods import Method
from ..problems import IsospectralProblem
from ..registry import ModelSpec, load_model
from ..threads import ThreadRequest, plan_threads
from .lock import WriteLock
from .reader import Checkpoint, Opened, iter_rows, open_result, read_checkpoint, run_state
from .rebuild import rebuild_run
from .recovery import recover
from .writer import HDF5Writer, check_writer_settings

__all__ = ["resume"]


def _rebuild(
    p: Path,
    config: dict[str, Any],
    meta: dict[str, Any],
    problem: IsospectralProblem | None,
    method: Method | None,
    model: ModelSpec | None,
    params: Mapping[str, Any] | None,
) -> tuple[IsospectralProblem, Method]:
    """The problem and method of the run, checked against what the file recorded."""
    if problem is None or method is None:
        if not config.get("model"):
            raise ResultFileError(
                f"{p}: the file's configuration names no registered model; pass problem= and "
                "method= to resume it"
            )
        # validated first: a configuration asking for a huge state is refused there, before
        # anything is allocated (its errors, ConfigError, say what is wrong themselves)
        prob_b, meth_b = rebuild_run(config, meta, model=model, params=params)
        problem = problem if problem is not None else prob_b
        method = method if method is not None else meth_b
    if not isinstance(method, Method):
        raise ResultFileError(f"{p}: method= must be a Method instance, got {method!r}")
    if method.name != meta["method"]:
        raise ResultFileError(f"{p}: the run used {meta['method']!r}, not {method.name!r}")
    if not isinstance(problem, IsospectralProblem):
        raise ResultFileError(f"{p}: problem= must be an IsospectralProblem, got {problem!r}")
    if problem.algebra.name != meta["algebra"]:
        raise ResultFileError(
            f"{p}: the run was on {meta['algebra']}, the problem given is on {problem.algebra.name}"
        )
    return problem, method


def _check_model(
    p: Path, meta: dict[str, Any], problem: IsospectralProblem, first: Any, force: bool
) -> None:
    """Refuse (unless ``force``) a problem whose fingerprint differs from the one the file
    recorded when its run started (files written before fingerprints record none)."""
    recorded = meta.get("model_fingerprint")
    if recorded is None or first is None or force:
        return
    changes = fingerprint_changes(recorded, model_fingerprint(problem, first))
    if changes:
        raise ModelChangedError(
            f"{p}: the model changed since the run started ({'; '.join(changes)}); resuming "
            "would mix two models in one file: restore the model, or resume with force=True "
            "(isoflow run --resume FILE --force) to continue with this one anyway",
            changes=changes,
        )


def _check_method(p: Path, meta: dict[str, Any], method: Method, force: bool) -> None:
    """Refuse (unless ``force``) a method whose settings differ from those the file recorded
    when its run started (files written before settings were recorded have none)."""
    if force:
        return
    changes = settings_changes(meta.get("method_settings"), method_settings(method))
    if changes:
        raise ResultFileError(
            f"{p}: the method's settings changed since the run started ({'; '.join(changes)}); "
            "resuming would continue on another path: give the run's method, or resume with "
            "force=True (isoflow run --resume FILE --force) to continue with this one anyway"
        )


def resume(
    path: str | os.PathLike[str],
    *,
    problem: IsospectralProblem | None = None,
    method: Method | None = None,
    model: ModelSpec | str | None = None,
    params: Mapping[str, Any] | None = None,
    progress: bool | None = None,
    throw: bool = True,
    chunk_rows: int | None = None,
    flush_seconds: float | None = None,
    force: bool = False,
    threads: ThreadRequest = None,
    status_every: float | None = None,
) -> Solution:
    """Continue a streamed run from its last checkpoint, appending to the same file.

    Parameters
    ----------
    path : str or Path
        A result file written by :class:`~isoflow.io.HDF5Writer` (complete, stopped or killed;
        a run that ended, complete or failed, is returned as it ended, and its file is not
        written: there is nothing to continue).
    problem, method : optional
        The run's problem and method; by default rebuilt from the file's configuration
        (:func:`~isoflow.io.rebuild.rebuild_run`). Needed for runs of problems you built
        yourself.
    model : ModelSpec or str, optional
        For a run of a model that is not built in (``"package.module:function"``, or a model
        registered by an installed package): the model, named again (a name is loaded with
        :func:`~isoflow.registry.load_model`, importing its module), checked to be the one the
        file recorded and rebuilt from the file's parameters.
    params : mapping, optional
        Model parameters given again (``isoflow run --resume FILE --param k=v``): each must
        equal the recorded value.
    progress, throw :
        As in :func:`isoflow.solve`.
    chunk_rows, flush_seconds :
        As in :class:`~isoflow.io.HDF5Writer`; by default those the run was written with
        (recorded in the file; 256 rows and 1 s for files that predate the record).
    force : bool
        Resume although the model differs from the one the run started with (see
        :class:`~isoflow.ModelChangedError`), or the method's settings do (its solver's
        tolerance, say); the file keeps the records of the first.
    threads : None, int or dict
        As in :func:`isoflow.solve`.
    status_every : float or None
        As in :func:`isoflow.solve`: a status line (step, steps per second, projected end)
        every this many seconds.

    Returns
    -------
    Solution
        As :func:`isoflow.solve` with a writer: the checkpoint state and the final state, and the
        drifts over all saved states of the file.

    Raises
    ------
    ModelChangedError
        The model is not the one the run started with: its ``B`` (or a function of its
        diagnostics) differs at the probe state the file's fingerprint recorded, or the
        source of the user code defining it changed (the file is left unchanged). Files
        written before isoflow recorded fingerprints are resumed without this check.
    ResultFileError
        Another process writes the file; the file is damaged or crafted; or the problem or
        method do not match the run it records: another space, method name, or (unless
        ``force``) method settings (the file is left unchanged).
    ConfigError
        The stored configuration does not rebuild the recorded run (another model than
        ``model``, a parameter that differs from ``params``, a size out of range, a model that
        is not built in and not named); the file is left unchanged.
    NotInSpaceError
        The checkpoint state is not in the problem's space (as :func:`isoflow.solve`).
    ParameterError
        A malformed ``threads``, or ``problem`` together with ``model`` or ``params`` (which
        rebuild the problem); checked before the file is touched.
    """
    plan_threads(threads)  # a malformed request is refused before anything else
    check_continue_options(progress, throw, status_every)
    check_flag(force, "force")
    check_writer_settings(chunk_rows, flush_seconds)  # those given (None: the recorded ones)
    if problem is not None and (model is not None or params):
        raise ParameterError(
            "model= and params= rebuild the run's problem: give them or problem=, not both"
        )
    if isinstance(model, str):
        model = load_model(model)  # the caller named it: this may import their module
    p = Path(path)
    if p.is_symlink():
        p = Path(os.path.realpath(p))
    if not p.exists():
        raise ResultFileError(f"{p}: no such file")
    lock = WriteLock(p)
    handed_over = False
    try:
        with open_result(p, check_live=False) as o:
            cp = read_checkpoint(o)
            if cp is None:
                raise o.fail("no checkpoint to resume from (start the run again)")
            ended = run_state(o, cp)[0] in ("complete", "failed")
            config, meta = o.config, o.meta
            needs_rewrite = o.version < 2 or o.flagged
            problem, method = _rebuild(p, config, meta, problem, method, model, params)
            method = method.for_problem(problem)  # as the run's start settled it
            t0, dt = float(meta["t0"]), float(meta["dt"])
            n_steps, save_every = int(meta["n_steps"]), int(meta["save_every"])
            if tuple(np.shape(cp.y)) != tuple(meta["state_shape"]):
                raise o.fail(f"checkpoint state shape {np.shape(cp.y)} is not the run's")
            state = RunState(cp.step, cp.y, cp.method_state, cp.failures)
            restart = check_restart(
                problem, method, state, t0=t0, dt=dt, n_steps=n_steps, save_every=save_every
            )
            # every row verified, and the drifts of the rows written accumulated
            acc = DiagnosticsAccumulator(problem)
            names = list(o.rows)
            first = None
            for blocks, data in iter_rows(o, cp, names):
                if blocks[0][0] == 0:
                    first = data["ys"][0]
                    acc.set_first_state(first)
                acc.absorb(data["ts"], {k: data[k] for k in names[2:]})
            _check_model(p, meta, problem, first, force)
            _check_method(p, meta, method, force)
            _check_series(o, problem)
            if ended:  # nothing to continue: the recorded run, the file untouched
                return _recorded(problem, cp, t0, dt, n_steps, acc)
        chunk_rows, flush_seconds = _writer_settings(meta, chunk_rows, flush_seconds)
        if needs_rewrite:
            cp = recover(p, chunk_rows)
        writer = HDF5Writer.reopen(
            p, lock, n_rows=cp.n_rows, n_blocks=cp.n_blocks, slot=cp.slot,
            last=(cp.step, cp.y, cp.method_state, cp.failures),
            chunk_rows=chunk_rows, flush_seconds=flush_seconds,
        )  # fmt: skip
        handed_over = True
    finally:
        if not handed_over:
            lock.release()
    return continue_run(
        restart, writer=writer, accumulator=acc, progress=progress, throw=throw, threads=threads,
        status_every=status_every,
    )  # fmt: skip


def _check_series(o: Opened, problem: IsospectralProblem) -> None:
    """The file's diagnostic series are the problem's: a resumed run appends to them and
    cannot add or drop one (even with ``force``)."""
    recorded = {k for k in o.rows if k not in ("ts", "ys")}
    expected = set(series_names(problem))
    extra, missing = sorted(recorded - expected), sorted(expected - recorded)
    if extra or missing:
        what = "; ".join(
            [f"the file's {', '.join(extra)}"] * bool(extra)
            + [f"the model's {', '.join(missing)}"] * bool(missing)
        )
        raise o.fail(
            f"the model's diagnostics differ from the file's ({what}): a resumed run appends to "
            "the file's series and cannot change them; start a new run"
        )


def _recorded(
    problem: IsospectralProblem, cp: Checkpoint, t0: float, dt: float, n_steps: int,
    acc: DiagnosticsAccumulator,
) -> Solution:  # fmt: skip
    """The :class:`Solution` of a run that ended (complete or failed) as its file records it:
    the last state, the statistics, status and message of the call that ended it, the drifts
    over every row."""
    info = cp.run_info or {}
    stats_any = info.get("stats")
    recorded: dict[str, Any] = stats_any if isinstance(stats_any, dict) else {}
    known = {f.name for f in dataclasses.fields(SolveStats)}
    stats = SolveStats(**{k: v for k, v in recorded.items() if k in known})
    batch = problem.algebra.batch_shape(cp.y)
    members = int(np.prod(batch, dtype=np.int64))
    fails = cp.failures if cp.failures is not None else MemberFailures.none(members)
    failed_step, reasons = failure_fields(fails, batch)
    status = int(info.get("status", RUN_FINISHED))
    return Solution(
        ts=np.array([t0 + cp.step * dt]), ys=np.asarray(cp.y)[None], stats=stats,
        success=status == RUN_FINISHED, status=status, message=str(info.get("message", "")),
        diagnostics=acc.result(), t0=t0, dt=dt, n_steps=n_steps, failed_step=failed_step,
        failure_reasons=reasons,
    )  # fmt: skip


def _writer_settings(
    meta: Mapping[str, Any], chunk_rows: int | None, flush_seconds: float | None
) -> tuple[int, float]:
    """``(chunk_rows, flush_seconds)`` of a resume: those given, else the run's recorded ones
    (the writer's defaults for a file without the record)."""
    recorded = meta.get("writer")
    recorded = recorded if isinstance(recorded, dict) else {}
    rows: Any = recorded.get("chunk_rows")
    if chunk_rows is None:
        ok = isinstance(rows, int) and not isinstance(rows, bool) and rows >= 1
        chunk_rows = int(rows) if ok else 256
    flush: Any = recorded.get("flush_seconds", 1.0)
    if flush_seconds is None:
        if flush is None:
            flush_seconds = math.inf  # the run wrote every chunk_rows states only
        else:
            ok = isinstance(flush, (int, float)) and not isinstance(flush, bool) and flush >= 0
            flush_seconds = float(flush) if ok else 1.0
    return chunk_rows, flush_seconds
