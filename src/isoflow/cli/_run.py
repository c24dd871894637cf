"""``isoflow run``: a model streamed to an HDF5 result file, and ``isoflow run --resume FILE``.

The command line is parsed here; the run is what :func:`isoflow.registry.layered_config` makes
of a TOML file and the options, and a resumed run is :func:`isoflow.io.resume`'s.
"""

from __future__ import annotations

import argparse
from typing import Any

from .. import registry
from .._version import __version__
from ._common import (
    UserError,
    add_thread_options,
    anderson_memory,
    announce_compiles,
    finite_float,
    positive_float,
    positive_int,
    progress,
    summary_lines,
    sweep_task_note,
)

__all__ = ["add_parser", "handle"]

#: The prefix of the destinations of the model-parameter flags (``--n`` stores ``param_n``).
_PARAM = "param_"


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


def add_parser(sub: Any) -> None:
    """Declare ``isoflow run`` on the subparsers ``sub``."""
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
    solvers = ", ".join(registry.SOLVERS)
    run.add_argument("--method", help="a method of 'isoflow list methods' (default isomp)")
    run.add_argument("--solver", help=f"one of: {solvers} (default fixed-point)")
    run.add_argument(
        "--rtol",
        type=positive_float,
        help="nonlinear solver tolerance (default 1e-14; 1e-8 for the *-cayley methods and "
        "for stochastic-isomp on spins and vortices with noise)",
    )
    run.add_argument(
        "--anderson",
        type=anderson_memory,
        metavar="M",
        help="Anderson memory of the fixed point (default 0: plain iteration)",
    )
    run.add_argument("--t0", type=finite_float, help="start time (default 0)")
    run.add_argument("--t1", type=finite_float, help="final time")
    run.add_argument("--dt", type=positive_float, help="step size")
    run.add_argument("--n-steps", type=positive_int, dest="n_steps", help="number of steps")
    run.add_argument(
        "--save-every", type=positive_int, dest="save_every", help="save every k steps (1)"
    )
    params = run.add_argument_group(
        "model parameters",
        "each flag sets a parameter of the built-in models its help names (isoflow list "
        "models); --param sets any parameter, also of your own model",
    )
    for flag, (name, users) in _model_param_flags().items():
        params.add_argument(
            flag, dest=f"{_PARAM}{name}", metavar="VALUE", help=_model_param_help(users)
        )
    params.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="any model parameter (repeatable; VALUE read as a TOML value)",
    )
    run.add_argument(
        "--chunk-rows",
        type=positive_int,
        default=None,
        help="states per write (default 256; on --resume the run's)",
    )
    run.add_argument(
        "--flush-seconds",
        type=positive_float,
        default=None,
        help="write the saved states and a checkpoint at least this often (default 1 s; on "
        "--resume the run's; a kill loses at most the steps since the last checkpoint)",
    )
    run.add_argument(
        "--status-every",
        type=positive_float,
        default=60.0,
        dest="status_every",
        metavar="SECONDS",
        help="a status line on stderr this often: step, steps per second, projected end "
        "(default 60 s, on --resume too; none with --quiet)",
    )
    run.add_argument("--quiet", action="store_true", help="no progress bar, no status lines")
    add_thread_options(run)
    run.set_defaults(handler=handle, computes=True)


def _model_name(args: argparse.Namespace) -> str | None:
    """The model named by the positional argument or ``--model`` (not two different ones)."""
    if args.model and args.model_option and args.model != args.model_option:
        raise UserError(f"two models given: {args.model!r} and --model {args.model_option!r}")
    return args.model or args.model_option  # type: ignore[no-any-return]


def _param_texts(args: argparse.Namespace) -> list[tuple[str, str]]:
    """The model parameters given as options, ``(key, text)`` in order: the flags (``--n 6``),
    then each ``--param KEY=VALUE``."""
    texts = [
        (key.removeprefix(_PARAM), value)
        for key, value in vars(args).items()
        if key.startswith(_PARAM) and value is not None
    ]
    for item in args.param:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise UserError(f"--param expects KEY=VALUE, got {item!r}")
        texts.append((key.strip(), value.strip()))
    return texts


def _resume(args: argparse.Namespace) -> int:
    from .. import io

    given = [
        k for k in ("config", "out", *registry.RUN_OPTIONS) if getattr(args, k) not in (None, False)
    ]
    given += [k for k in vars(args) if k.startswith(_PARAM) and getattr(args, k) is not None]
    if given:
        flags = ", ".join("--" + k.removeprefix(_PARAM).replace("_", "-") for k in given)
        raise UserError(
            f"--resume continues the run the file records; {flags} cannot change it "
            "(only --model and --param, to name your model again)"
        )
    about = io.info(args.resume)
    note = sweep_task_note(args.resume, about["config"])
    if note is not None:
        raise UserError(f"{args.resume} is {note}")
    name = _model_name(args)
    if name is None and args.param:
        raise UserError("--param on --resume needs the model too (--model SPEC)")
    spec = registry.load_model(name) if name is not None else None  # the user named it
    params = registry.parse_params(spec, _param_texts(args)) if spec is not None else None
    announce_compiles()
    sol = io.resume(
        args.resume,
        model=spec,
        params=params,
        progress=progress(args),
        throw=False,
        chunk_rows=args.chunk_rows,
        flush_seconds=args.flush_seconds,
        force=args.force,
        status_every=None if args.quiet else args.status_every,
    )
    if about["state"] in ("complete", "failed"):  # resume checked it and wrote nothing
        how = "failed" if about["state"] == "failed" else "is complete"
        steps = f"{about['step']} of {about['meta']['n_steps']} steps"
        print(
            f"{args.resume}: the run {how} ({steps}): nothing to resume "
            f"(isoflow info {args.resume} shows it)"
        )
        return 0 if sol.success else 1
    print("\n".join(summary_lines(f"resumed {args.resume}", sol, args.resume)))
    return 0 if sol.success else 1


def handle(args: argparse.Namespace) -> int:
    """Run (or resume) and print the summary; exit status 0 when the run succeeded."""
    if args.resume:
        return _resume(args)
    from .. import io
    from .._solve import solve

    spec, cfg, toml_out = registry.layered_config(
        args.config,
        model=_model_name(args),
        params=_param_texts(args),
        options={k: getattr(args, k) for k in registry.RUN_OPTIONS},
    )
    out = args.out or toml_out
    if not out:
        raise UserError("give the result file with --out FILE (or out = ... in the TOML)")
    writer = io.HDF5Writer(
        out,
        cfg,
        chunk_rows=256 if args.chunk_rows is None else args.chunk_rows,
        flush_seconds=1.0 if args.flush_seconds is None else args.flush_seconds,
        force=args.force,
    )  # refuses an existing file without --force, and anything that is not a regular file
    problem, y0, method, kwargs = registry.build(cfg, model=spec)
    announce_compiles()
    sol = solve(
        problem, method, y0, **kwargs, progress=progress(args), throw=False, writer=writer,
        status_every=None if args.quiet else args.status_every,
    )  # fmt: skip
    params = ", ".join(f"{k} = {v}" for k, v in cfg["params"].items())
    title = f"isoflow {__version__} run: {cfg['model']} ({params}), {method.name}"
    print("\n".join(summary_lines(title, sol, out)))
    return 0 if sol.success else 1
