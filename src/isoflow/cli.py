"""The ``isoflow`` command line: it parses and prints; the work is library calls.

Commands:

* ``isoflow demo``: the paper's so(10) rigid body with IsoMP, printing invariant drifts;
* ``isoflow run MODEL ... --out FILE`` (or ``--config run.toml``): a model of
  :mod:`isoflow.registry` (built in, registered by an installed package, or your own
  ``--model package.module:factory``) streamed to an HDF5 result file; ``isoflow run --resume
  FILE`` continues a stopped or killed run bit for bit;
* ``isoflow info FILE``: what a result file holds, its parameters and invariant drifts (or a
  sweep directory: its tasks, failed members and worst drifts);
* ``isoflow sweep SWEEP.toml --out DIR``: a sweep of :mod:`isoflow.sweep` on dask.distributed;
* ``isoflow plot FILE --out PNG``: invariants and state components from a result file;
* ``isoflow reproduce NAME|all --out DIR [--quick]``: the paper's experiments, figures and JSON;
* ``isoflow list [models|methods|solvers|experiments]``: the names the other commands take;
* ``isoflow bench ...``: the benchmark suite of a source checkout (``benchmarks/run_all.py``).

User mistakes end with a one-line ``isoflow: error: ...`` on stderr and a non-zero exit status
(2 for a bad command line, 1 otherwise), never a traceback. Set ``ISOFLOW_DEBUG=1`` to see the
traceback of an error anyway. Modules beyond the numerical core (HDF5, matplotlib, numba) are
imported only by the commands that use them, after the command line has been parsed.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
import warnings
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from . import registry
from ._errors import IsoflowError
from ._version import __version__

__all__ = ["main"]


class UserError(IsoflowError):
    """A mistake on the command line or in a configuration file."""


# ---- argument types ----------------------------------------------------------------------------


def _finite_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be finite: {text!r}")
    return value


def _positive_float(text: str) -> float:
    value = _finite_float(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be positive: {text!r}")
    return value


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1: {text!r}")
    return value


def _anderson(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if not 0 <= value <= registry.ANDERSON_MAX:
        raise argparse.ArgumentTypeError(f"must be in 0..{registry.ANDERSON_MAX}: {text!r}")
    return value


def _model_param_flags() -> dict[str, tuple[str, list[tuple[str, registry.Param]]]]:
    """Command-line flag -> (model parameter name, the built-in models that have it)."""
    flags: dict[str, tuple[str, list[tuple[str, registry.Param]]]] = {}
    for spec in registry.MODELS.values():
        for name, param in (spec.params or {}).items():
            flag = "--vortex-config" if name == "config" else f"--{name.replace('_', '-')}"
            flags.setdefault(flag, (name, []))[1].append((spec.name, param))
    return flags


def _model_param_help(users: list[tuple[str, registry.Param]]) -> str:
    """The help of a model-parameter flag: what it means for each model that has it."""
    parts = []
    for model, p in users:
        default = "" if p.default is None else f" (default {p.typed(p.default)})"
        parts.append(f"{model}: {p.help}{default}")
    return "; ".join(parts).replace("%", "%%")


#: Options of ``run`` that describe a new run (not taken by ``--resume``).
_RUN_OPTIONS = ("method", "solver", "rtol", "anderson", "t0", "t1", "dt", "n_steps", "save_every")


# ---- the parser --------------------------------------------------------------------------------


def _add_thread_options(parser: argparse.ArgumentParser, default: Any = argparse.SUPPRESS) -> None:
    """``--threads`` and ``--blas-threads`` (on the main parser and on every command that
    computes; a command's own flags leave the main parser's value alone unless given)."""
    parser.add_argument(
        "--threads",
        type=_positive_int,
        default=default,
        metavar="K",
        help=(
            "cores a run may use: numba threads when its compiled loop runs ensemble members "
            "in parallel, else BLAS threads (default: 1 BLAS thread, numba on every core; "
            "see iso.threads)"
        ),
    )
    parser.add_argument(
        "--blas-threads",
        type=_positive_int,
        default=default,
        metavar="K",
        help="BLAS/OpenMP threads (default 1); numba gets the cores they leave",
    )


def _build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="isoflow",
        description="Structure-preserving integration of isospectral flows (IsoMP).",
    )
    parser.add_argument("--version", action="version", version=f"isoflow {__version__}")
    _add_thread_options(parser, default=None)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    solvers = ", ".join(registry.SOLVERS)

    demo = sub.add_parser(
        "demo",
        help="integrate the paper's so(n) rigid body and print invariant drifts",
        description=(
            "Generalized rigid body on so(n) (paper, Sec. 3.1, with the symmetrized inertia), "
            "integrated by IsoMP. Prints the drift of the Casimirs (eigenvalues), of the "
            "Hamiltonian and of the distance to so(n)."
        ),
    )
    demo.add_argument("--n", type=_positive_int, default=10, help="matrix size (default 10)")
    demo.add_argument("--dt", type=_positive_float, default=0.1, help="step size (default 0.1)")
    demo.add_argument("--t1", type=_positive_float, default=100.0, help="final time (default 100)")
    demo.add_argument(
        "--solver",
        choices=tuple(registry.SOLVERS),
        default="fixed-point",
        help="nonlinear solver for the stage (default fixed-point)",
    )
    demo.add_argument(
        "--anderson", type=_anderson, default=0, metavar="M", help="Anderson memory (0: plain)"
    )
    demo.add_argument("--quiet", action="store_true", help="no progress bar")
    _add_thread_options(demo)
    demo.set_defaults(func=_demo, computes=True)

    models_help = "; ".join(f"{k}: {v.description}" for k, v in registry.MODELS.items())
    run = sub.add_parser(
        "run",
        help="integrate a model and stream the states to an HDF5 result file",
        description=(
            "Integrate a model with a fixed step and stream the saved states, their invariants "
            "and checkpoints to HDF5. Options override values of --config. Built-in models: "
            f"{models_help}. Your own: --model package.module:factory (a function returning "
            "(problem, initial_state), its keyword arguments from --param KEY=VALUE or the "
            "TOML [params] table), or the name a package registers under the entry-point group "
            f"{registry.ENTRY_POINT_GROUP}."
        ),
    )
    run.add_argument("model", nargs="?", help=f"one of: {', '.join(registry.MODELS)}")
    run.add_argument(
        "--model",
        dest="model_option",
        metavar="SPEC",
        help="the model by name or as package.module:factory (needed to resume such a run)",
    )
    run.add_argument("--config", metavar="TOML", help="read the run from a TOML file")
    run.add_argument("--resume", metavar="FILE", help="continue a stopped or killed run")
    run.add_argument("--out", metavar="FILE", help="result file (HDF5) to write")
    run.add_argument(
        "--force",
        action="store_true",
        help="overwrite an existing --out file; with --resume: continue although the model "
        "changed since the run started",
    )
    run.add_argument("--method", help="a method of 'isoflow list methods' (default isomp)")
    run.add_argument("--solver", help=f"one of: {solvers} (default fixed-point)")
    run.add_argument("--rtol", type=_positive_float, help="nonlinear solver tolerance")
    run.add_argument(
        "--anderson", type=_anderson, metavar="M", help="Anderson memory of the fixed point"
    )
    run.add_argument("--t0", type=_finite_float, help="start time (default 0)")
    run.add_argument("--t1", type=_finite_float, help="final time")
    run.add_argument("--dt", type=_positive_float, help="step size")
    run.add_argument("--n-steps", type=_positive_int, dest="n_steps", help="number of steps")
    run.add_argument(
        "--save-every", type=_positive_int, dest="save_every", help="save every k steps (1)"
    )
    params = run.add_argument_group(
        "model parameters",
        "each flag sets a parameter of the built-in models its help names (isoflow list "
        "models); --param sets any parameter, also of your own model",
    )
    for flag, (name, users) in _model_param_flags().items():
        params.add_argument(
            flag, dest=f"param_{name}", metavar="VALUE", help=_model_param_help(users)
        )
    params.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="any model parameter (repeatable; VALUE read as a TOML value)",
    )
    run.add_argument(
        "--chunk-rows", type=_positive_int, default=256, help="states per write (default 256)"
    )
    run.add_argument(
        "--flush-seconds",
        type=_positive_float,
        default=1.0,
        help="write at least this often (default 1 s)",
    )
    run.add_argument("--quiet", action="store_true", help="no progress bar")
    _add_thread_options(run)
    run.set_defaults(func=_run, computes=True)

    info = sub.add_parser(
        "info",
        help="describe a result file: parameters and invariant drifts",
        description=(
            "Describe an isoflow result file: the model and its parameters, the method, the "
            "time grid, how far the run got and whether it can be resumed (isoflow run "
            "--resume FILE), and the drift of every invariant over the saved states. On a "
            "sweep directory: its tasks, failed members and worst drifts."
        ),
    )
    info.add_argument("file", help="an isoflow result file (HDF5) or a sweep directory")
    info.add_argument("--json", action="store_true", help="print JSON")
    info.add_argument(
        "--verify",
        action="store_true",
        help="also check every saved state's checksum (a sweep: every task file's SHA-256)",
    )
    info.set_defaults(func=_info, computes=False)

    _add_sweep_parser(sub)

    plot = sub.add_parser(
        "plot",
        help="plot invariants and states from a result file",
        description=(
            "Draw a result file: the variation of the Casimirs, of the Hamiltonian (or the "
            "Lyapunov function; no panel when the problem has neither), of the problem's "
            "invariants (or the distance to the space), and up to six state components that "
            "move, against time. Writes PNG, PDF or SVG by the suffix of --out."
        ),
    )
    plot.add_argument("file", help="an isoflow result file (HDF5)")
    plot.add_argument("--out", required=True, help="image file (.png, .pdf, .svg)")
    plot.add_argument("--force", action="store_true", help="replace an existing --out file")
    plot.set_defaults(func=_plot, computes=False)

    experiments = tuple(registry.EXPERIMENTS)
    rep = sub.add_parser(
        "reproduce",
        help="run the paper's experiments: figures and JSON summaries",
        description=(
            "Run experiments of the paper (Section 3, corrected conventions) and write a PNG and "
            "a PDF figure and a JSON summary for each (replacing those of an earlier run). "
            "Experiments: " + ", ".join(experiments)
        ),
    )
    rep.add_argument(
        "experiment",
        choices=("all", *experiments),
        metavar="EXPERIMENT",
        help="'all' or one of: " + ", ".join(experiments),
    )
    rep.add_argument("--out", default="results", help="output directory (default results/)")
    rep.add_argument("--quick", action="store_true", help="reduced versions (CI, a first look)")
    rep.add_argument("--no-pdf", action="store_true", help="PNG only")
    rep.add_argument("--quiet", action="store_true", help="no progress bars")
    _add_thread_options(rep)
    rep.set_defaults(func=_reproduce, computes=True)

    lst = sub.add_parser(
        "list", help="the models, methods, solvers and experiments, by the names to use"
    )
    lst.add_argument(
        "what",
        nargs="?",
        choices=("models", "methods", "solvers", "experiments"),
        help="one kind only (default: all)",
    )
    lst.set_defaults(func=_list, computes=False)

    bench = sub.add_parser(
        "bench",
        help="run the benchmark suite of a source checkout (ratios to baselines; JSON + table)",
        description=(
            "Run benchmarks/run_all.py of the source tree this isoflow is installed from "
            "(pip install -e .). The benchmarks are not part of the installed package."
        ),
    )
    bench.add_argument("--out", default="benchmark-results", help="output directory")
    bench.add_argument("--quick", action="store_true", help="smaller sizes (about a minute)")
    bench.add_argument(
        "--only", metavar="K,...", help="benchmark numbers (default: all; checked by the suite)"
    )
    bench.add_argument("--figure", metavar="PNG", help="write the spin-chain-cost figure here")
    bench.set_defaults(func=_bench, computes=False)
    return parser


# ---- shared ------------------------------------------------------------------------------------


def _announce_compiles() -> None:
    """Say on stderr when a run compiles, also in runs without a progress bar (``--quiet``)."""
    from . import _compile_clock

    _compile_clock.SHOW = True


def _progress(args: argparse.Namespace) -> bool | None:
    return False if args.quiet else None


def _table(rows: Sequence[tuple[str, str]]) -> list[str]:
    """``name  value`` lines, indented two spaces, the values aligned after the longest name."""
    width = max((len(name) for name, _ in rows), default=0)
    return [f"  {name:<{width}}  {value}" for name, value in rows]


def _threads_text(threads: dict[str, Any]) -> str:
    """``SolveStats.threads`` in words: ``"1 BLAS, 2 numba (2 cores)"``."""
    return (
        f"{threads.get('blas', '?')} BLAS, {threads.get('numba', '?')} numba "
        f"({threads.get('cores', '?')} cores)"
    )


def _summary_lines(title: str, sol: Any, path: str | None = None) -> list[str]:
    d = sol.diagnostics.summary() if sol.diagnostics is not None else {}
    st = sol.stats
    rows = [
        ("steps", f"{st.n_steps} of {sol.n_steps}"),
        (
            "wall time",
            f"{st.wall_time:.2f} s"
            + (f" (compiling {st.compile_time:.1f} s)" if st.compile_time > 0.5 else ""),
        ),
        ("runner", st.runner),
        ("threads", _threads_text(st.threads)),
        ("iterations per step", f"mean {st.iterations_mean:.2f}, max {st.iterations_max}"),
        *((k, f"{v:.3e}") for k, v in d.items()),
        ("status", sol.message),
    ]
    if path is not None:
        rows.append(("file", path))
    return [title, *_table(rows)]


# ---- demo --------------------------------------------------------------------------------------


def _demo(args: argparse.Namespace) -> int:
    from ._solve import solve

    config = {
        "model": "rigid-body",
        "params": {"n": args.n},
        "method": "isomp",
        "solver": args.solver,
        "anderson": args.anderson,
        "dt": args.dt,
        "t1": args.t1,
        "save_every": max(1, round(1.0 / args.dt)),
    }
    problem, W0, method, kwargs = registry.build(config)
    _announce_compiles()
    # one step first, so that loading the compiled kernels is not counted as stepping
    solve(problem, method, W0, dt=args.dt, n_steps=1, progress=False)
    start = time.perf_counter()
    sol = solve(problem, method, W0, **kwargs, progress=_progress(args))
    wall = time.perf_counter() - start
    d = sol.diagnostics.summary() if sol.diagnostics is not None else {}
    solver = args.solver + (f", Anderson {args.anderson}" if args.anderson else "")
    rows = [
        ("steps", f"{sol.stats.n_steps}"),
        (
            "wall time",
            f"{wall:.3f} s ({1e6 * wall / max(sol.stats.n_steps, 1):.1f} us/step, warm)",
        ),
        (
            "iterations per step",
            f"mean {sol.stats.iterations_mean:.2f}, max {sol.stats.iterations_max}",
        ),
        ("Casimir drift", f"{d['casimir_drift']:.2e}  (eigenvalues, relative to ||W0||)"),
        (
            "Hamiltonian drift",
            f"{d['hamiltonian_relative_drift']:.2e}  (relative; bounded, O(h^2))",
        ),
        (f"distance to so({args.n})", f"{d['max_distance']:.2e}"),
        ("status", sol.message),
    ]
    lines = [
        f"isoflow {__version__} demo: generalized rigid body on so({args.n}), IsoMP "
        f"({solver}), h = {args.dt:g}, T = {args.t1:g}",
        *(f"  {name:<22} {value}" for name, value in rows),
    ]
    print("\n".join(lines))
    return 0 if sol.success else 1


# ---- run ---------------------------------------------------------------------------------------


def _read_toml(path: str) -> dict[str, Any]:
    from . import registry

    return registry.read_toml(path, "configuration file", UserError)


def _model_name(args: argparse.Namespace) -> str | None:
    if args.model and args.model_option and args.model != args.model_option:
        raise UserError(f"two models given: {args.model!r} and --model {args.model_option!r}")
    return args.model or args.model_option  # type: ignore[no-any-return]


def _cli_params(args: argparse.Namespace, spec: registry.ModelSpec) -> dict[str, Any]:
    """Model parameters given as options (``--n 6``, ``--param k=v``), converted."""
    params: dict[str, Any] = {}
    for key, value in vars(args).items():
        if key.startswith("param_") and value is not None:
            name = key[len("param_") :]
            params[name] = registry.parse_param(spec, name, value)
    for item in args.param:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise UserError(f"--param expects KEY=VALUE, got {item!r}")
        params[key.strip()] = registry.parse_param(spec, key.strip(), value.strip())
    return params


def _run_config(args: argparse.Namespace) -> tuple[registry.ModelSpec, dict[str, Any], str | None]:
    """The model, the run configuration (normalized) and the output path."""
    table = _read_toml(args.config) if args.config else {}
    cfg, out = registry.config_from_toml(table)
    name = _model_name(args)
    if name is not None:
        if cfg.get("model") not in (None, name):
            cfg.pop("params", None)  # the TOML's parameters belong to another model
        cfg["model"] = name
    if not cfg.get("model"):
        raise UserError("name a model (isoflow run MODEL ...) or give --config run.toml")
    spec = registry.load_model(cfg["model"])  # the user named it: this may import their module
    cli_params = _cli_params(args, spec)
    if cli_params:
        given = cfg.get("params") or {}
        if not isinstance(given, dict):
            raise registry.ConfigError(f"params must be a table of model parameters, got {given!r}")
        cfg["params"] = given | cli_params
    for key in _RUN_OPTIONS:
        value = getattr(args, key)
        if value is not None:
            cfg[key] = value
    if sum(getattr(args, k) is not None for k in ("t1", "dt", "n_steps")) == 2:
        for k in ("t1", "dt", "n_steps"):  # two options replace the file's choice of two
            if getattr(args, k) is None:
                cfg.pop(k, None)
    cfg["model"] = spec.name
    return spec, registry.normalize_config(cfg, model=spec), args.out or out


def _resume(args: argparse.Namespace) -> int:
    from . import io

    extra = [k for k in ("config", "out", *_RUN_OPTIONS) if getattr(args, k) not in (None, False)]
    extra += [k for k in vars(args) if k.startswith("param_") and getattr(args, k) is not None]
    if extra:
        flags = ", ".join("--" + k.removeprefix("param_").replace("_", "-") for k in extra)
        raise UserError(
            f"--resume continues the run the file records; {flags} cannot change it "
            "(only --model and --param, to name your model again)"
        )
    common = {
        "progress": _progress(args),
        "throw": False,
        "chunk_rows": args.chunk_rows,
        "flush_seconds": args.flush_seconds,
        "force": args.force,
    }
    sweep_note = _sweep_task_note(args.resume, io.info(args.resume)["config"])
    if sweep_note is not None:
        raise UserError(f"{args.resume} is {sweep_note}")
    name = _model_name(args)
    if name is None:
        if args.param:
            raise UserError("--param on --resume needs the model too (--model SPEC)")
        _announce_compiles()
        sol = io.resume(args.resume, **common)
    else:
        data = io.info(args.resume)
        spec = registry.load_model(name)
        cfg = registry.check_recorded_model(data["config"], spec, _cli_params(args, spec))
        problem, y0, method, _kw = registry.build(cfg, model=spec)
        registry.check_recorded_state(data["meta"], problem, y0)
        _announce_compiles()
        sol = io.resume(args.resume, problem=problem, method=method, **common)
    print("\n".join(_summary_lines(f"resumed {args.resume}", sol, args.resume)))
    return 0 if sol.success else 1


def _run(args: argparse.Namespace) -> int:
    if args.resume:
        return _resume(args)
    from . import io
    from ._solve import solve

    spec, cfg, out = _run_config(args)
    if not out:
        raise UserError("give the result file with --out FILE (or out = ... in the TOML)")
    writer = io.HDF5Writer(
        out, cfg, chunk_rows=args.chunk_rows, flush_seconds=args.flush_seconds, force=args.force
    )  # refuses an existing file without --force, and anything that is not a regular file
    problem, y0, method, kwargs = registry.build(cfg, model=spec)
    _announce_compiles()
    sol = solve(problem, method, y0, **kwargs, progress=_progress(args), throw=False, writer=writer)
    params = ", ".join(f"{k} = {v}" for k, v in cfg["params"].items())
    title = f"isoflow {__version__} run: {cfg['model']} ({params}), {method.name}"
    print("\n".join(_summary_lines(title, sol, out)))
    return 0 if sol.success else 1


# ---- info / plot -------------------------------------------------------------------------------


def _info(args: argparse.Namespace) -> int:
    from . import io

    if Path(args.file).is_dir():
        return _info_sweep(args)

    data = io.info(args.file, verify_states=args.verify)
    if args.json:
        print(json.dumps(data, indent=2))
        return 0
    cfg, meta, run_info = data["config"], data["meta"], data["run_info"]
    sweep_note = _sweep_task_note(args.file, cfg)
    message = data["state_message"]
    if sweep_note is not None:  # resumed by its sweep, not by isoflow run
        message = message.split("; resume with isoflow run --resume")[0]
    state = f"{data['state']}: {message}".rstrip(": ")
    model = str(cfg.get("model", "(not registered)"))
    if "model" in cfg and model not in registry.MODELS and sweep_note is None:
        model += " (not built in" + (
            f": resume with --model {model})" if data["resumable"] else ")"
        )
    rows = [
        ("model", f"{model} " + json.dumps(cfg.get("params", {}))),
        ("method", f"{meta.get('method')} (solver {cfg.get('solver') or 'none'})"),
        ("algebra", f"{meta.get('algebra')}, state shape {tuple(meta.get('state_shape'))}"),
        (
            "time grid",
            f"t0 = {meta.get('t0'):g}, dt = {meta.get('dt'):g}, {meta.get('n_steps')} steps, "
            f"save every {meta.get('save_every')}",
        ),
        ("state", state),
        (
            "resumable",
            ("yes" if data["resumable"] else "no")
            + (f" (writer: {data['writer']})" if data["writer"] else ""),
        ),
        (
            "format version",
            f"{data['format_version']}"
            + (", every saved state verified" if data["verified"] else ""),
        ),
        ("steps done", f"{data['step']}"),
        ("saved states", f"{data['n_saved']} (last t = {data['t_last']})"),
    ]
    if run_info is not None:
        st = run_info.get("stats", {})
        rows.append(
            (
                "wall time",
                f"{st.get('wall_time', float('nan')):.2f} s "
                f"(iterations mean {st.get('iterations_mean', float('nan')):.2f})",
            )
        )
        if isinstance(st.get("threads"), dict):  # older files do not record them
            rows.append(("threads", _threads_text(st["threads"])))
    rows += [(k, f"{v:.3e}") for k, v in data["drifts"].items()]
    if sweep_note is not None:
        rows.append(("sweep", sweep_note))
    head = (
        f"{data['path']}: isoflow result file (written by isoflow {data['isoflow_version']}, "
        f"{data['created']})"
    )
    print("\n".join([head, *_table(rows)]))
    return 0


# ---- sweeps (isoflow.sweep) ---------------------------------------------------------------------


def _add_sweep_parser(sub: Any) -> None:
    sw = sub.add_parser(
        "sweep",
        help="run a sweep (sweep.toml: a model, a method, a table of members) on dask",
        description=(
            "Run the members of a sweep file as batched ensembles in dask workers, each task "
            "streamed to DIR/tasks/<id>.h5; run it again to resume. Needs isoflow[sweep]. "
            "Exit status 0: every member finished; 1: a member failed, a task raised, or an "
            "error (one line); 2: a bad command line."
        ),
    )
    sw.add_argument("file", help="the sweep file (TOML; see the user guide's page on sweeps)")
    sw.add_argument("--out", metavar="DIR", help="the sweep directory (default: the file's out)")
    where = sw.add_mutually_exclusive_group()
    where.add_argument(
        "--workers",
        type=_positive_int,
        metavar="K",
        help="local worker processes (default and most: the cores available)",
    )
    where.add_argument("--scheduler", metavar="ADDR", help="a running dask scheduler to use")
    sw.add_argument(
        "--connect-timeout",
        type=_positive_float,
        default=30.0,
        metavar="SECONDS",
        help="how long to wait for --scheduler to answer (default 30 s)",
    )
    sw.add_argument(
        "--retries", type=int, default=2, metavar="R", help="worker deaths a task survives (2)"
    )
    sw.add_argument("--quiet", action="store_true", help="no progress")
    sw.set_defaults(func=_sweep, computes=False)


@contextmanager
def _warnings_as_lines() -> Iterator[None]:
    """Show warnings as one ``isoflow: warning: ...`` line each on stderr."""

    def show(message: Any, category: Any, *args: Any, **kwargs: Any) -> None:
        print(f"isoflow: warning: {' '.join(str(message).split())}", file=sys.stderr)

    with warnings.catch_warnings():
        warnings.showwarning = show
        yield


def _sweep(args: argparse.Namespace) -> int:
    from .sweep import read_spec, run
    from .sweep.spec import require_extra

    require_extra("dask", "distributed", "xarray")
    spec = read_spec(args.file)
    with _warnings_as_lines():
        result = run(
            spec,
            args.out,
            scheduler=args.scheduler,
            workers=args.workers,
            retries=args.retries,
            connect_timeout=args.connect_timeout,
            progress=not args.quiet,
        )
    print(result)
    for tid, msg in result.redone.items():
        print(f"  task {tid} redone: {msg}")
    for tid, msg in result.errors.items():
        print(f"  task {tid} raised: {msg}")
    if result.failed_members:
        shown = ", ".join(map(str, result.failed_members[:20]))
        more = len(result.failed_members) - 20
        shown += f" and {more} more" if more > 0 else ""
        print(f"  failed members: {shown} (isoflow info {result.path})")
    return 0 if result.success else 1


def _info_sweep(args: argparse.Namespace) -> int:
    from .sweep import status

    data = status(args.file, verify=args.verify)
    if args.json:
        print(json.dumps(data, indent=2))
        return 0
    run = data["run"]
    rows = [
        (
            "time grid",
            f"t0 = {run['t0']:g}, dt = {run['dt']:g}, {run['n_steps']} steps, "
            f"save every {run['save_every']}",
        ),
        (
            "members",
            f"{data['members']} in {data['tasks']} task"
            + ("" if data["tasks"] == 1 else "s")
            + ("" if data["perturb"] is None else f" (perturb {data['perturb']:g})"),
        ),
        (
            "tasks",
            f"{data['done']} done, {data['partial']} partial, {data['pending']} not started"
            + (f", {len(data['damaged'])} damaged" if data["damaged"] else "")
            + (", every result file verified" if args.verify else ""),
        ),
    ]
    rows += [(f"task {tid}", f"damaged: {msg}") for tid, msg in data["damaged"].items()]
    rows += [(f"task {tid}", f"raised: {msg}") for tid, msg in data["errors"].items()]
    rows += [
        (f"member {i}", f"failed at step {f['step']}: {f['message']}")
        for i, f in data["failed_members"].items()
    ]
    rows += [(k, f"{v:.3e} (worst finished member)") for k, v in data["drifts"].items()]
    head = f"{data['path']}: isoflow sweep, model {data['model']}, method {run.get('method')}"
    print("\n".join([head, *_table(rows)]))
    return 0


def _sweep_task_note(path: str, config: dict[str, Any]) -> str | None:
    """For a sweep's task file: how to continue it (running its sweep again), else ``None``."""
    mark = config.get("sweep")
    if not isinstance(mark, dict):
        return None
    directory = Path(path).resolve().parent.parent
    return (
        f"task {mark.get('task')} of the sweep in {directory}: run the sweep again to resume "
        f"it (isoflow sweep SWEEP.toml --out {directory}), not isoflow run --resume"
    )


def _plot(args: argparse.Namespace) -> int:
    from . import io, plotting

    run = io.load(args.file)
    fig = plotting.plot_run(run)
    plotting.save(fig, args.out, force=args.force)
    print(f"wrote {args.out}")
    return 0


# ---- reproduce / list --------------------------------------------------------------------------


def _reproduce(args: argparse.Namespace) -> int:
    from .experiments import run_experiment

    names = list(registry.EXPERIMENTS) if args.experiment == "all" else [args.experiment]
    out = Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"cannot create output directory {out}: {exc.strerror}") from None
    _announce_compiles()
    start = time.perf_counter()
    for name in names:
        t = time.perf_counter()
        files = run_experiment(
            name, out, quick=args.quick, pdf=not args.no_pdf, progress=_progress(args)
        )
        print(f"{name:<24} {time.perf_counter() - t:7.1f} s  " + " ".join(str(f) for f in files))
    print(f"{'total':<24} {time.perf_counter() - start:7.1f} s")
    return 0


def _list(args: argparse.Namespace) -> int:
    kinds = [args.what] if args.what else ["models", "methods", "solvers", "experiments"]
    lines: list[str] = []
    for kind in kinds:
        lines.append(f"{kind}:")
        for name, text, params in registry.describe(kind):
            lines.append(f"  {name:<34} {text}")
            lines += [f"  {'':<34}   {p}" for p in params]
    if "models" in kinds:
        lines.append(
            "  (your own: --model package.module:factory; packages register models under the "
            f"entry-point group {registry.ENTRY_POINT_GROUP})"
        )
    print("\n".join(lines))
    return 0


# ---- bench -------------------------------------------------------------------------------------


def _source_tree() -> Path | None:
    """The repository this isoflow is installed from (an editable install), if any."""
    root = Path(__file__).resolve().parents[2]
    if (root / "benchmarks" / "run_all.py").is_file() and (root / "pyproject.toml").is_file():
        return root
    return None


def _bench(args: argparse.Namespace) -> int:
    root = _source_tree()
    if root is None:
        raise UserError(
            "the benchmarks live in the source repository, not in the installed package: clone "
            "it, install it with pip install -e . and run isoflow bench (or python "
            "benchmarks/run_all.py) there"
        )
    cmd = [sys.executable, str(root / "benchmarks" / "run_all.py"), "--out", args.out]
    if args.quick:
        cmd.append("--quick")
    if args.only:
        cmd += ["--only", args.only]
    if args.figure:
        cmd += ["--figure", args.figure]
    return subprocess.run(cmd, check=False).returncode


# ---- entry point -------------------------------------------------------------------------------


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``isoflow`` command; returns the exit status."""
    parser = _build_parser()
    args = parser.parse_args(list(sys.argv[1:] if argv is None else argv))
    from . import _compile_clock

    announced = _compile_clock.SHOW  # the commands announce compilations; restored after
    try:
        if not args.computes:
            return int(args.func(args))
        from .threads import thread_limits

        if args.threads is not None and args.blas_threads is not None:
            raise UserError("give --threads or --blas-threads, not both")
        with thread_limits(blas=args.blas_threads, threads=args.threads):
            return int(args.func(args))
    except BrokenPipeError:  # the reader went away (isoflow list | head): stop quietly
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 1
    except (IsoflowError, OSError, ValueError, TypeError, MemoryError) as exc:
        if os.environ.get("ISOFLOW_DEBUG"):
            raise
        msg = " ".join(str(exc).split()) or type(exc).__name__
        if isinstance(exc, MemoryError):
            msg = f"out of memory: {msg} (a smaller model, or a machine with more memory)"
        print(f"isoflow: error: {msg}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("isoflow: interrupted", file=sys.stderr)
        return 130
    finally:
        _compile_clock.SHOW = announced


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
