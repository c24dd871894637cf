"""The ``isoflow`` command line.

Commands:

* ``isoflow demo``: the paper's so(10) rigid body with IsoMP, printing invariant drifts;
* ``isoflow run MODEL ... --out FILE`` (or ``--config run.toml``): any registered model and
  method, streamed to an HDF5 result file; ``isoflow run --resume FILE`` continues a stopped or
  killed run bit for bit;
* ``isoflow info FILE``: what a result file holds, its parameters and invariant drifts;
* ``isoflow plot FILE --out PNG``: invariants and state components from a result file;
* ``isoflow reproduce NAME|all --out DIR [--quick]``: the paper's experiments, figures and JSON.

User mistakes end with a one-line ``isoflow: error: ...`` on stderr and a non-zero exit status
(2 for a bad command line, 1 otherwise), never a traceback. Set ``ISOFLOW_DEBUG=1`` to see the
traceback of an error anyway.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import tomllib
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from . import __version__
from ._errors import IsoflowError

__all__ = ["main"]


class UserError(IsoflowError):
    """A mistake on the command line or in a configuration file."""


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not np.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"must be positive and finite: {text!r}")
    return value


def _finite_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not np.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be finite: {text!r}")
    return value


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1: {text!r}")
    return value


def _model_param_flags() -> dict[str, str]:
    """Command-line flag -> model parameter name, for every registered model's parameters."""
    from .registry import MODELS

    flags: dict[str, str] = {}
    for spec in MODELS.values():
        for name in spec.params:
            flag = "--vortex-config" if name == "config" else f"--{name.replace('_', '-')}"
            flags[flag] = name
    return flags


def _build_parser() -> argparse.ArgumentParser:
    from .experiments import EXPERIMENTS
    from .registry import METHODS, MODELS, SOLVERS

    parser = argparse.ArgumentParser(
        prog="isoflow",
        description="Structure-preserving integration of isospectral flows (IsoMP).",
    )
    parser.add_argument("--version", action="version", version=f"isoflow {__version__}")
    parser.add_argument(
        "--blas-threads",
        type=_positive_int,
        default=None,
        metavar="K",
        help=(
            "BLAS threads (default 1: the paper's states are small and idle BLAS threads "
            "spin against the compiled kernels; raise it for large dense states); numba gets "
            "the remaining cores (iso.threads.thread_limits)"
        ),
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    demo = sub.add_parser(
        "demo",
        help="integrate the paper's so(n) rigid body and print invariant drifts",
        description=(
            "Generalized rigid body on so(n) (paper, Sec. 3.1, with the symmetrized inertia of "
            "NOTES.md), integrated by IsoMP. Prints the drift of the Casimirs (eigenvalues), of "
            "the Hamiltonian and of the distance to so(n)."
        ),
    )
    demo.add_argument("--n", type=_positive_int, default=10, help="matrix size (default 10)")
    demo.add_argument("--dt", type=_positive_float, default=0.1, help="step size (default 0.1)")
    demo.add_argument("--t1", type=_positive_float, default=100.0, help="final time (default 100)")
    demo.add_argument(
        "--solver",
        choices=("fixed-point", "newton", "newton-krylov"),
        default="fixed-point",
        help="nonlinear solver for the stage (default fixed-point)",
    )
    demo.add_argument("--quiet", action="store_true", help="no progress bar")
    demo.set_defaults(func=_demo)

    models_help = "; ".join(f"{k}: {v.description}" for k, v in MODELS.items())
    run = sub.add_parser(
        "run",
        help="integrate a model and stream the states to an HDF5 result file",
        description=(
            "Integrate a registered model with a fixed step and stream the saved states, their "
            "invariants and checkpoints to HDF5. Options override values of --config. "
            f"Models: {models_help}."
        ),
    )
    run.add_argument("model", nargs="?", help=f"one of: {', '.join(MODELS)}")
    run.add_argument("--config", metavar="TOML", help="read the run from a TOML file")
    run.add_argument("--resume", metavar="FILE", help="continue a stopped or killed run")
    run.add_argument("--out", metavar="FILE", help="result file (HDF5) to write")
    run.add_argument("--force", action="store_true", help="overwrite an existing --out file")
    run.add_argument("--method", help=f"one of: {', '.join(METHODS)} (default isomp)")
    run.add_argument("--solver", help=f"one of: {', '.join(SOLVERS)} (default fixed-point)")
    run.add_argument("--rtol", type=_positive_float, help="nonlinear solver tolerance")
    run.add_argument("--t0", type=_finite_float, help="start time (default 0)")
    run.add_argument("--t1", type=_finite_float, help="final time")
    run.add_argument("--dt", type=_positive_float, help="step size")
    run.add_argument("--n-steps", type=_positive_int, dest="n_steps", help="number of steps")
    run.add_argument(
        "--save-every", type=_positive_int, dest="save_every", help="save every k steps (1)"
    )
    for flag, name in _model_param_flags().items():
        run.add_argument(
            flag, dest=f"param_{name}", metavar="VALUE", help=f"model parameter {name}"
        )
    run.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="any model parameter (repeatable)",
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
    run.set_defaults(func=_run)

    info = sub.add_parser("info", help="describe a result file: parameters and invariant drifts")
    info.add_argument("file", help="an isoflow result file (HDF5)")
    info.add_argument("--json", action="store_true", help="print JSON")
    info.set_defaults(func=_info)

    plot = sub.add_parser("plot", help="plot invariants and states from a result file")
    plot.add_argument("file", help="an isoflow result file (HDF5)")
    plot.add_argument("--out", required=True, help="image file (.png, .pdf, .svg)")
    plot.set_defaults(func=_plot)

    rep = sub.add_parser(
        "reproduce",
        help="run the paper's experiments: figures and JSON summaries",
        description=(
            "Run experiments of the paper (Section 3, corrected conventions) and write a PNG and "
            "a PDF figure and a JSON summary for each. Experiments: " + ", ".join(EXPERIMENTS)
        ),
    )
    rep.add_argument(
        "experiment",
        choices=("all", *EXPERIMENTS),
        metavar="EXPERIMENT",
        help="'all' or one of: " + ", ".join(EXPERIMENTS),
    )
    rep.add_argument("--out", default="results", help="output directory (default results/)")
    rep.add_argument("--quick", action="store_true", help="reduced versions (CI, a first look)")
    rep.add_argument("--no-pdf", action="store_true", help="PNG only")
    rep.add_argument("--quiet", action="store_true", help="no progress bars")
    rep.set_defaults(func=_reproduce)

    bench = sub.add_parser(
        "bench",
        help="run the benchmark suite (speed as ratios to baselines; JSON + table)",
        description="Run benchmarks/ 1-7; see 'isoflow bench --help' for its options.",
        add_help=False,
    )
    bench.add_argument("bench_args", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)
    bench.set_defaults(func=_bench)
    return parser


# --- demo ---------------------------------------------------------------------------------------


def _demo(args: argparse.Namespace) -> int:
    from . import FixedPoint, IsoMP, Newton, solve
    from .models import rigid_body

    solver = {
        "fixed-point": FixedPoint(),
        "newton": Newton(),
        "newton-krylov": Newton(jacobian="krylov"),
    }[args.solver]
    problem, W0 = rigid_body(n=args.n)
    # one step first, so that loading the compiled kernels is not counted as stepping
    solve(problem, IsoMP(solver=solver), W0, dt=args.dt, n_steps=1, progress=False)
    start = time.perf_counter()
    sol = solve(
        problem,
        IsoMP(solver=solver),
        W0,
        dt=args.dt,
        t1=args.t1,
        save_every=max(1, round(1.0 / args.dt)),
        progress=False if args.quiet else None,
    )
    wall = time.perf_counter() - start
    assert sol.diagnostics is not None
    d = sol.diagnostics.summary()
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
        f"({args.solver}), h = {args.dt:g}, T = {args.t1:g}",
        *(f"  {name:<22} {value}" for name, value in rows),
    ]
    print("\n".join(lines))
    return 0 if sol.success else 1


# --- run ----------------------------------------------------------------------------------------


def _read_toml(path: str) -> dict[str, Any]:
    p = Path(path)
    try:
        with p.open("rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise UserError(f"{p}: no such configuration file") from None
    except tomllib.TOMLDecodeError as exc:
        raise UserError(f"{p}: malformed TOML: {exc}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise UserError(f"{p}: cannot read configuration: {exc}") from None


def _run_config(args: argparse.Namespace) -> tuple[dict[str, Any], str | None]:
    """The run configuration (registry form) and the output path, from TOML and options."""
    cfg: dict[str, Any] = _read_toml(args.config) if args.config else {}
    out = cfg.pop("out", None)
    params = dict(cfg.get("params") or {})
    if args.model:
        if cfg.get("model") and cfg["model"] != args.model:
            params = {}  # the TOML's parameters belong to another model
        cfg["model"] = args.model
    for key in ("method", "solver", "rtol", "t0", "t1", "dt", "n_steps", "save_every"):
        value = getattr(args, key)
        if value is not None:
            cfg[key] = value
    if sum(getattr(args, k) is not None for k in ("t1", "dt", "n_steps")) == 2:
        for k in ("t1", "dt", "n_steps"):  # two options replace the file's choice of two
            if getattr(args, k) is None:
                cfg.pop(k, None)
    for key, value in vars(args).items():
        if key.startswith("param_") and value is not None:
            params[key[len("param_") :]] = value
    for item in args.param:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise UserError(f"--param expects KEY=VALUE, got {item!r}")
        params[key.strip()] = value.strip()
    cfg["params"] = params
    if args.out:
        out = args.out
    return cfg, out


def _summary_lines(title: str, sol: Any, path: str) -> list[str]:
    d = sol.diagnostics.summary() if sol.diagnostics is not None else {}
    lines = [
        title,
        f"  {'steps':<24} {sol.stats.n_steps} of {sol.n_steps}",
        f"  {'wall time':<24} {sol.stats.wall_time:.2f} s",
        *(f"  {k:<24} {v:.3e}" for k, v in d.items()),
        f"  {'status':<24} {sol.message}",
        f"  {'file':<24} {path}",
    ]
    return lines


def _run(args: argparse.Namespace) -> int:
    from . import io, solve
    from .registry import build, normalize_config

    progress = False if args.quiet else None
    if args.resume:
        if args.model or args.config:
            raise UserError("--resume takes the run from the file; give no model or --config")
        sol = io.resume(
            args.resume,
            progress=progress,
            throw=False,
            chunk_rows=args.chunk_rows,
            flush_seconds=args.flush_seconds,
        )
        print("\n".join(_summary_lines(f"resumed {args.resume}", sol, args.resume)))
        return 0 if sol.success else 1
    if not args.model and not args.config:
        raise UserError("name a model (isoflow run MODEL ...) or give --config run.toml")
    cfg, out = _run_config(args)
    cfg = normalize_config(cfg)
    if not out:
        raise UserError("give the result file with --out FILE (or out = ... in the TOML)")
    if Path(out).exists() and not args.force:
        raise UserError(f"{out} exists (use --force to overwrite, or --resume {out} to continue)")
    problem, y0, method, kwargs = build(cfg)
    writer = io.HDF5Writer(out, cfg, chunk_rows=args.chunk_rows, flush_seconds=args.flush_seconds)
    sol = solve(problem, method, y0, **kwargs, progress=progress, throw=False, writer=writer)
    params = ", ".join(f"{k} = {v}" for k, v in cfg["params"].items())
    title = f"isoflow {__version__} run: {cfg['model']} ({params}), {method.name}"
    print("\n".join(_summary_lines(title, sol, out)))
    return 0 if sol.success else 1


# --- info / plot ---------------------------------------------------------------------------------


def _info(args: argparse.Namespace) -> int:
    from . import io

    data = io.info(args.file)
    if args.json:
        print(json.dumps(data, indent=2))
        return 0
    cfg, meta, run_info = data["config"], data["meta"], data["run_info"]
    if data["complete"]:
        state = "complete"
    elif run_info is None:
        state = "incomplete: stopped without closing (killed?); resume with isoflow run --resume"
    else:
        state = f"incomplete: {run_info.get('message', '')}"
    lines = [
        f"{data['path']}: isoflow result file (written by isoflow {data['isoflow_version']}, "
        f"{data['created']})",
        f"  {'model':<24} {cfg.get('model', '(not registered)')} "
        + json.dumps(cfg.get("params", {})),
        f"  {'method':<24} {meta.get('method')} (solver {cfg.get('solver', '?')})",
        f"  {'algebra':<24} {meta.get('algebra')}, state shape {tuple(meta.get('state_shape'))}",
        f"  {'time grid':<24} t0 = {meta.get('t0'):g}, dt = {meta.get('dt'):g}, "
        f"{meta.get('n_steps')} steps, save every {meta.get('save_every')}",
        f"  {'steps done':<24} {data['step']} ({state})",
        f"  {'saved states':<24} {data['n_saved']} (last t = {data['t_last']})",
    ]
    if run_info is not None:
        st = run_info.get("stats", {})
        lines.append(
            f"  {'wall time':<24} {st.get('wall_time', float('nan')):.2f} s "
            f"(iterations mean {st.get('iterations_mean', float('nan')):.2f})"
        )
    lines += [f"  {k:<24} {v:.3e}" for k, v in data["drifts"].items()]
    print("\n".join(lines))
    return 0


def _plot(args: argparse.Namespace) -> int:
    from . import io, plotting

    run = io.load(args.file)
    fig = plotting.plot_run(run)
    plotting.save(fig, args.out)
    print(f"wrote {args.out}")
    return 0


# --- reproduce ----------------------------------------------------------------------------------


def _reproduce(args: argparse.Namespace) -> int:
    from .experiments import EXPERIMENTS, run_experiment

    names = list(EXPERIMENTS) if args.experiment == "all" else [args.experiment]
    out = Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"cannot create output directory {out}: {exc.strerror}") from None
    start = time.perf_counter()
    for name in names:
        t = time.perf_counter()
        files = run_experiment(
            name, out, quick=args.quick, pdf=not args.no_pdf, progress=False if args.quiet else None
        )
        print(f"{name:<24} {time.perf_counter() - t:7.1f} s  " + " ".join(str(f) for f in files))
    print(f"{'total':<24} {time.perf_counter() - start:7.1f} s")
    return 0


def _bench(args: argparse.Namespace) -> int:
    from .benchmarking import main as bench_main

    return int(bench_main(list(args.bench_args)))


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``isoflow`` command; returns the exit status."""
    words = list(sys.argv[1:] if argv is None else argv)
    if words[:1] == ["bench"]:  # its own options, parsed by isoflow.benchmarking
        from .benchmarking import main as bench_main

        return int(bench_main(words[1:]))
    parser = _build_parser()
    args = parser.parse_args(words)
    try:
        from .threads import thread_limits

        with thread_limits(blas=args.blas_threads or 1):
            return int(args.func(args))
    except (IsoflowError, OSError, ValueError, TypeError) as exc:
        if os.environ.get("ISOFLOW_DEBUG"):
            raise
        msg = " ".join(str(exc).split()) or type(exc).__name__
        print(f"isoflow: error: {msg}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("isoflow: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
