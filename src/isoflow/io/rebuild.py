"""The problem and method of a recorded run, rebuilt from its configuration and checked.

A result file records its run's configuration (:mod:`isoflow.registry` form) and metadata
(space, state shape). :func:`rebuild_run` builds the problem and the method from them, the
one way :func:`~isoflow.io.resume` (and so ``isoflow run --resume``) does: for a built-in
model from the file alone; for a model that is not built in only when the user names it again
(a :class:`~isoflow.registry.ModelSpec` from :func:`~isoflow.registry.load_model`), checked
to be the model the file recorded (:func:`check_recorded_model`). The rebuilt model must still
build the recorded space and state shape (:func:`check_recorded_state`).
"""

from __future__ import annotations

import inspect
from collections.abc import Mapping
from typing import Any

import numpy as np

from ..methods import Method
from ..problems import IsospectralProblem
from ..registry import MODELS, ConfigError, ModelSpec, build, check_model_name, normalize_config

__all__ = ["check_recorded_model", "check_recorded_state", "rebuild_run"]


def rebuild_run(
    config: Mapping[str, Any],
    meta: Mapping[str, Any],
    *,
    model: ModelSpec | None = None,
    params: Mapping[str, Any] | None = None,
) -> tuple[IsospectralProblem, Method]:
    """The problem and method of the run a result file recorded.

    Parameters
    ----------
    config, meta : mapping
        The file's run configuration and metadata.
    model : ModelSpec, optional
        The model, named again by the user; required for a model that is not built in.
    params : mapping, optional
        Model parameters the user gave again (of ``model``, else of the built-in model the
        file names); each must equal the recorded value.

    Raises
    ------
    ConfigError
        The configuration does not rebuild the recorded run: it is malformed or asks for a
        size out of bounds (refused before anything is allocated), names a model that is not
        built in and not handed over, another model than ``model``, a parameter that differs
        from ``params``, or the model now builds another space or state shape.
    """
    if model is None and params:
        model = MODELS.get(check_model_name(config.get("model")))
    if model is not None:
        cfg = check_recorded_model(config, model, params)
    else:
        cfg = normalize_config(config)
    problem, y0, method, _kwargs = build(_recorded_tolerance(cfg, meta), model=model)
    check_recorded_state(meta, problem, y0)
    return problem, method


def _recorded_tolerance(cfg: dict[str, Any], meta: Mapping[str, Any]) -> dict[str, Any]:
    """``cfg`` with the solver tolerance its run recorded when it set none.

    A configuration without ``rtol`` ran at its method's default of the time, which the file
    records (``meta["method_settings"]``, ``solver.rtol`` or, for a split step or a
    composition, ``base.solver.rtol``); the rebuilt method takes that one, so that a resume
    continues at the run's tolerance even where a later version's default differs (the
    stochastic midpoint on spins with noise: ``1e-8`` since 2026-11-27, ``1e-14`` before).
    """
    settings = meta.get("method_settings") or {}
    rtol = settings.get("solver.rtol", settings.get("base.solver.rtol"))
    if not isinstance(rtol, (int, float)) or isinstance(rtol, bool) or not rtol > 0:
        return cfg
    if "solver" in cfg and cfg.get("rtol") is None:
        return dict(cfg, rtol=float(rtol))
    return cfg


def check_recorded_model(
    recorded: Mapping[str, Any], model: ModelSpec, params: Mapping[str, Any] | None = None
) -> dict[str, Any]:
    """Check that ``model`` (named again by the user) is the model a result file recorded.

    Parameters
    ----------
    recorded : mapping
        The configuration stored in the file.
    model : ModelSpec
        The model the user named (:func:`~isoflow.registry.load_model`).
    params : mapping, optional
        Parameters the user gave again; each must equal the recorded value.

    Returns
    -------
    dict
        The recorded configuration, normalized with ``model``.

    Raises
    ------
    ConfigError
        Another model, or a parameter that differs from the recorded one.
    """
    name = check_model_name(recorded.get("model")) if "model" in recorded else None
    if name != model.name:
        raise ConfigError(
            f"the file was written by model {name!r}, not {model.name!r}; name the model the "
            "run used"
        )
    cfg = normalize_config(recorded, model=model)
    if params:
        merged = dict(recorded.get("params") or {}) | dict(params)
        again = normalize_config(dict(recorded, params=merged), model=model)["params"]
        for key in params:
            if key in cfg["params"]:
                was, what = cfg["params"][key], "recorded in the file"
            else:  # not recorded: the run took the model function's default
                was, what = _function_default(model, key), "(the model function's default)"
            if not _same_value(again.get(key), was):
                raise ConfigError(
                    f"parameter {key} = {again.get(key)!r} differs from the run's "
                    f"{key} = {was!r} {what}"
                )
    return cfg


def _function_default(model: ModelSpec, key: str) -> Any:
    """The default of the model function's keyword ``key`` (``None`` if it has none or
    cannot be read)."""
    try:
        found = inspect.signature(model.function()).parameters.get(key)
    except (TypeError, ValueError):
        return None
    if found is None or found.default is inspect.Parameter.empty:
        return None
    return found.default


def _same_value(a: Any, b: Any) -> bool:
    """``a == b``, lists and tuples compared entry by entry (TOML gives lists)."""
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same_value(x, y) for x, y in zip(a, b, strict=True))
    try:
        return bool(a == b)
    except (TypeError, ValueError):
        return False


def check_recorded_state(meta: Mapping[str, Any], problem: IsospectralProblem, y0: Any) -> None:
    """Check that a rebuilt model has the space and state shape a result file recorded.

    Parameters
    ----------
    meta : mapping
        The file's metadata (``algebra``, ``state_shape``; a missing key is not checked).
    problem : IsospectralProblem
        The rebuilt problem.
    y0 : array_like
        The rebuilt initial state.

    Raises
    ------
    ConfigError
        The model now builds another space or state shape (its code or defaults changed).
    """
    algebra = meta.get("algebra")
    if algebra is not None and algebra != problem.algebra.name:
        raise ConfigError(
            f"the model now builds a problem on {problem.algebra.name}, the file's run was on "
            f"{algebra}"
        )
    shape = meta.get("state_shape")
    if shape is not None and list(np.shape(y0)) != list(shape):
        raise ConfigError(
            f"the model now builds states of shape {tuple(np.shape(y0))}, the file's run had "
            f"{tuple(shape)}"
        )
