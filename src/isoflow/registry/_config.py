"""Run configurations: checking them, reading them from TOML, layering options, building runs.

A run configuration is a flat dictionary::

    {"model": "rigid-body", "params": {"n": 10}, "method": "isomp", "solver": "fixed-point",
     "rtol": 1e-14, "anderson": 0, "t0": 0.0, "dt": 0.1, "t1": 100.0, "save_every": 10}

:func:`normalize_config` checks one and fills in the defaults (what result files record);
:func:`config_from_toml` and :func:`read_toml` read one from a TOML file; :func:`layered_config`
is the rule of ``isoflow run``: a TOML file overridden by command-line options; :func:`build`
turns one into ``(problem, y0, method, solve_kwargs)``. The rule "two of ``t1``, ``dt``,
``n_steps``" is :func:`isoflow._solve.time_grid`'s; this module only calls it.
"""

from __future__ import annotations

import tomllib
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .._errors import IsoflowError
from .._solve import time_grid
from ..methods import Method
from ..nonlinear import NonlinearSolver
from ..problems import IsospectralProblem
from ..splitting import has_split_part
from ._catalogue import MODELS, ModelSpec, check_model_name, load_model
from ._methods import ANDERSON_MAX, METHODS, SOLVERS, make_method, make_solver, split_method
from ._params import ConfigError, Param, choice, json_value, parse_params

__all__ = [
    "RUN_OPTIONS",
    "build",
    "config_from_toml",
    "layered_config",
    "normalize_config",
    "read_toml",
]

#: The keys of a run configuration besides ``model`` and ``params``: each one an option of
#: ``isoflow run`` too (``n_steps`` as ``--n-steps``).
RUN_OPTIONS = ("method", "solver", "rtol", "anderson", "t0", "t1", "dt", "n_steps", "save_every")

_RUN_KEYS = frozenset({"model", "params", *RUN_OPTIONS})

#: The time-grid keys, of which a configuration gives two.
_TIME_KEYS = ("t1", "dt", "n_steps")


def _number(value: Any, kind: type, what: str) -> Any:
    return Param(kind, None, "").check(value, what)


def normalize_config(config: Mapping[str, Any], *, model: ModelSpec | None = None) -> dict:
    """Check a run configuration and fill in the defaults; returns a new JSON-ready dict.

    Parameters
    ----------
    config : mapping
        See :mod:`isoflow.registry`. Values must have their types (``dt = 0.1``, not ``"0.1"``).
    model : ModelSpec, optional
        The model, when it is not built in (from :func:`load_model`); without it, the
        parameters of such a model are only checked to be plain values. Nothing is imported.

    Raises
    ------
    ConfigError
        Unknown keys, model, method, solver or parameter, a value of the wrong type or out of
        bounds, a solver option that the method or solver does not take.
    StepSizeError, TimeSpanError, ParameterError
        From :func:`isoflow._solve.time_grid`: not two of ``t1``, ``dt``, ``n_steps``, or a
        span that is not a whole number of steps.
    """
    if not isinstance(config, Mapping):
        raise ConfigError(
            f"a run configuration must be a table/dictionary, got {type(config).__name__}"
        )
    unknown = set(config) - _RUN_KEYS
    if unknown:
        raise ConfigError(
            f"unknown option(s) {', '.join(sorted(map(str, unknown)))} "
            f"(known: {', '.join(sorted(_RUN_KEYS))})"
        )
    if "model" not in config:
        raise ConfigError("the configuration names no model")
    name = check_model_name(config["model"])
    if model is not None:
        if model.name != name:
            raise ConfigError(f"the configuration names model {name!r}, not {model.name!r}")
        spec: ModelSpec | None = model
    elif name in MODELS:
        spec = MODELS[name]
    else:
        spec = None  # a user's model: checked generically, never imported from here
    given = config.get("params", {})
    if given is None:
        given = {}
    if not isinstance(given, Mapping):
        raise ConfigError(f"params must be a table of model parameters, got {given!r}")
    params: dict[str, Any] = {}
    if spec is not None and spec.params is not None:
        for key, value in given.items():
            if key not in spec.params:
                known = ", ".join(spec.params) or "none"
                raise ConfigError(f"model {name!r} has no parameter {key!r} (parameters: {known})")
            if value is not None:
                params[key] = spec.params[key].check(value, f"{name} {key}")
        for key, p in spec.params.items():
            if key not in params and p.default is not None:
                params[key] = list(p.default) if isinstance(p.default, list) else p.default
    else:
        params = {str(k): json_value(v, f"{name} {k}") for k, v in given.items()}

    method = choice(config.get("method", "isomp"), METHODS, "method")
    out: dict[str, Any] = {"model": name, "params": params, "method": method}
    if METHODS[method].implicit:
        solver = choice(config.get("solver", "fixed-point"), SOLVERS, "solver")
        rtol = config.get("rtol")
        if rtol is not None:
            rtol = _number(rtol, float, "rtol")
            if rtol <= 0:
                raise ConfigError(f"rtol must be positive, got {rtol!r}")
        else:
            rtol = METHODS[method].default_rtol  # None: the solver's own default
        anderson = _number(config.get("anderson", 0), int, "anderson")
        if not 0 <= anderson <= ANDERSON_MAX:
            raise ConfigError(f"anderson must be in 0..{ANDERSON_MAX}, got {anderson}")
        if anderson and not SOLVERS[solver].anderson:
            raise ConfigError(
                f"anderson = {anderson} is an option of the fixed-point solver, not of {solver!r}"
            )
        out |= {"solver": solver, "rtol": rtol}
        if SOLVERS[solver].anderson:
            out["anderson"] = anderson
    else:
        for key in ("solver", "rtol", "anderson"):
            if config.get(key) is not None:
                raise ConfigError(
                    f"method {method!r} is explicit: it takes no nonlinear solver "
                    f"(remove {key} = {config[key]!r})"
                )
    out["t0"] = _number(config.get("t0", 0.0), float, "t0")
    out["save_every"] = _number(config.get("save_every", 1), int, "save_every")
    if out["save_every"] < 1:
        raise ConfigError(f"save_every must be >= 1, got {out['save_every']}")
    times: dict[str, Any] = {}
    for key, kind in (("dt", float), ("t1", float), ("n_steps", int)):
        if config.get(key) is not None:
            times[key] = _number(config[key], kind, key)
    time_grid(out["t0"], times.get("t1"), times.get("dt"), times.get("n_steps"))
    return out | times


def config_from_toml(table: Mapping[str, Any]) -> tuple[dict[str, Any], str | None]:
    """Split a TOML run file into the run configuration and ``out`` (the result file).

    Parameters
    ----------
    table : mapping
        The parsed TOML file (its top-level table).

    Returns
    -------
    config : dict
        The run options (everything but ``out``), not yet normalized.
    out : str or None
        The result file, or ``None`` when the file names none.

    Raises
    ------
    ConfigError
        ``out`` that is not a string (the rest is checked by :func:`normalize_config`).
    """
    cfg = dict(table)
    out = cfg.pop("out", None)
    if out is not None and not (isinstance(out, str) and out):
        raise ConfigError(f"out must be a file name (a string), got {out!r}")
    unknown = set(cfg) - _RUN_KEYS
    if unknown:  # here, so that the keys listed include the file's own ``out``
        raise ConfigError(
            f"unknown option(s) {', '.join(sorted(map(str, unknown)))} "
            f"(known: {', '.join(sorted(_RUN_KEYS | {'out'}))})"
        )
    return cfg, out


def read_toml(path: str | Path, what: str, error: type[Exception] = IsoflowError) -> dict:
    """The table of the TOML file ``path``.

    Raises
    ------
    error
        One line naming ``path``: it does not exist, is not valid TOML, or cannot be read
        (``what`` names the kind of file in the message).
    """
    p = Path(path)
    try:
        with p.open("rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise error(f"{p}: no such {what}") from None
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{p}: malformed TOML: {' '.join(str(exc).split())}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise error(f"{p}: cannot read the {what}: {exc}") from None


def build(
    config: Mapping[str, Any], *, model: ModelSpec | None = None
) -> tuple[IsospectralProblem, Any, Method, dict[str, Any]]:
    """``(problem, y0, method, solve_kwargs)`` from a run configuration.

    ``solve_kwargs`` holds ``t0``, ``save_every`` and two of ``dt``, ``t1``, ``n_steps``,
    ready for ``iso.solve(problem, method, y0, **solve_kwargs)``.

    Parameters
    ----------
    config : mapping
        A run configuration (checked with :func:`normalize_config`). A model with
        dissipation or forcing (a linear part or forcing terms) gets the configured method as
        the isospectral part of a split step (:func:`~isoflow.registry.split_method`).
    model : ModelSpec, optional
        Required when the configuration names a model that is not built in: this function
        never imports a module because a configuration (e.g. one read from a result file)
        names it.

    Raises
    ------
    ConfigError
        See :func:`normalize_config`; a model that is not built in and not handed over.
    """
    cfg = normalize_config(config, model=model)
    if model is None:
        if cfg["model"] not in MODELS:
            raise ConfigError(
                f"the configuration names model {cfg['model']!r}, which is not built in; "
                "isoflow does not import code because a configuration names it: name the model "
                f"yourself (isoflow run --resume FILE --model {cfg['model']}, or "
                f"iso.io.resume(path, model={cfg['model']!r}))"
            )
        model = MODELS[cfg["model"]]
    problem, y0 = model.make(cfg["params"])
    spec = METHODS[cfg["method"]]
    solver: NonlinearSolver | None = None  # explicit, or the method's default for the problem
    defaults = cfg.get("solver") == "fixed-point" and cfg.get("rtol") is None
    if spec.implicit and not (spec.solver_by_problem and defaults and not cfg.get("anderson")):
        solver = make_solver(cfg["solver"], rtol=cfg["rtol"], anderson=cfg.get("anderson", 0))
    method = make_method(cfg["method"], solver)
    if has_split_part(problem):  # dissipation or forcing: the method runs as a split step
        method = split_method(method, problem)
    kwargs: dict[str, Any] = {
        k: cfg[k] for k in ("t0", "dt", "t1", "n_steps", "save_every") if k in cfg
    }
    return problem, np.asarray(y0), method, kwargs


def layered_config(
    path: str | Path | None,
    *,
    model: str | None = None,
    params: Iterable[tuple[str, str]] = (),
    options: Mapping[str, Any] | None = None,
) -> tuple[ModelSpec, dict[str, Any], str | None]:
    """The run of ``isoflow run``: a TOML run file, if any, overridden by command-line options.

    Parameters
    ----------
    path : str or Path, optional
        The TOML run file (``--config``).
    model : str, optional
        The model named on the command line. It replaces the file's model, and then the file's
        ``params`` too (they belong to the other model).
    params : iterable of (str, str)
        Model parameters given as command-line words (``--n 6``, ``--param k=v``), in order:
        read for the model by :func:`~isoflow.registry.parse_params`, they override the
        file's.
    options : mapping, optional
        Values of :data:`RUN_OPTIONS` given on the command line, of their types (``None``: not
        given). Each replaces the file's value; two of ``t1``, ``dt``, ``n_steps`` replace
        the file's choice of two.

    Returns
    -------
    spec : ModelSpec
        The model (:func:`~isoflow.registry.load_model`: the user named it, so a module of
        their own is imported).
    config : dict
        The run configuration, normalized (:func:`normalize_config`).
    out : str or None
        The result file the TOML file names (``out``).

    Raises
    ------
    ConfigError
        A run file that cannot be read, no model named, or any mistake
        :func:`normalize_config` finds.
    """
    table = read_toml(path, "configuration file", ConfigError) if path is not None else {}
    cfg, out = config_from_toml(table)
    if model is not None:
        if cfg.get("model") not in (None, model):
            cfg.pop("params", None)  # the file's parameters belong to another model
        cfg["model"] = model
    if not cfg.get("model"):
        raise ConfigError("name a model (isoflow run MODEL ...) or give --config run.toml")
    spec = load_model(cfg["model"])
    given = parse_params(spec, params)
    if given:
        recorded = cfg.get("params") or {}
        if not isinstance(recorded, dict):
            raise ConfigError(f"params must be a table of model parameters, got {recorded!r}")
        cfg["params"] = recorded | given
    options = {k: v for k, v in (options or {}).items() if v is not None}
    if sum(k in options for k in _TIME_KEYS) == 2:
        for k in _TIME_KEYS:  # two options replace the file's choice of two
            cfg.pop(k, None)
    cfg |= options
    cfg["model"] = spec.name
    return spec, normalize_config(cfg, model=spec), out
