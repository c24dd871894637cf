"""Names for models, methods and solvers, so that a run is described by plain JSON/TOML.

A run configuration is a flat dictionary (what ``isoflow run`` takes from its options or a TOML
file, and what :mod:`isoflow.io` stores as JSON in a result file)::

    {"model": "rigid-body", "params": {"n": 10}, "method": "isomp", "solver": "fixed-point",
     "rtol": 1e-14, "t0": 0.0, "dt": 0.1, "t1": 100.0, "save_every": 10}

Method names are flat: a composition is ``"<base>-<scheme>"`` (e.g. ``"isomp-suzuki-4"``,
``"spherical-midpoint-kahan-li-8"``), the Gauss IsoSyRK methods are ``"isosyrk-1"`` ..
``"isosyrk-3"``, so a configuration needs no extra key.

:func:`build` turns it back into ``(problem, y0, method, solve keyword arguments)``, which is how
a run is resumed from its file.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ._errors import IsoflowError
from .methods import RK4, ClassicalMidpoint, Composition, IsoMP, IsoSyRK, Method, SphericalMidpoint
from .methods.composition import SCHEMES
from .models import (
    brockett,
    euler_sphere,
    heisenberg_chain,
    hyperbolic_vortices,
    rigid_body,
    toda,
)
from .nonlinear import FixedPoint, Newton
from .problems import IsospectralProblem

__all__ = [
    "METHODS",
    "MODELS",
    "SOLVERS",
    "ConfigError",
    "ModelSpec",
    "build",
    "normalize_config",
]


class ConfigError(IsoflowError, ValueError):
    """A run configuration names an unknown model/method/option or has a bad value."""


@dataclass(frozen=True)
class ModelSpec:
    """A model function and its user-settable parameters.

    Attributes
    ----------
    func : callable
        ``func(**params) -> (IsospectralProblem, y0)``.
    params : dict
        Parameter name -> ``(type, default, help)``; ``type`` is ``int``, ``float`` or ``str``.
    description : str
    """

    func: Callable[..., tuple[IsospectralProblem, Any]]
    params: dict[str, tuple[type, Any, str]]
    description: str


MODELS: dict[str, ModelSpec] = {
    "rigid-body": ModelSpec(
        rigid_body,
        {"n": (int, 10, "matrix size of so(n)")},
        "generalized rigid body on so(n), the paper's inertia and W0 (Sec. 3.1)",
    ),
    "brockett": ModelSpec(
        brockett,
        {
            "n": (int, 10, "matrix size of herm(n)"),
            "seed": (int, 0, "seed of the random Hermitian W0"),
            "scale": (float, None, "norm scale of W0 (default: the model's)"),
        },
        "Brockett double bracket flow, N = diag(1..n) (Sec. 3.2)",
    ),
    "toda": ModelSpec(
        toda,
        {"n": (int, 12, "number of particles"), "seed": (int, 0, "seed of the initial data")},
        "non-periodic Toda lattice on sym(n), Flaschka form",
    ),
    "spin-chain": ModelSpec(
        heisenberg_chain,
        {
            "N": (int, 100, "number of spins"),
            "initial": (str, "curve", "'curve' (the paper's) or 'random'"),
            "seed": (int, 0, "seed for initial = 'random'"),
        },
        "periodic Heisenberg spin chain on (R^3, x)^N (Sec. 3.3)",
    ),
    "hyperbolic-vortices": ModelSpec(
        hyperbolic_vortices,
        {"config": (int, 1, "the paper's initial configuration, 1 or 2")},
        "three point vortices on the hyperbolic plane, sl(2,R)^3 (Sec. 3.4)",
    ),
    "euler-sphere": ModelSpec(
        euler_sphere,
        {
            "N": (int, 128, "matrix size of su(N): degrees l <= N - 1"),
            "omega": (float, 0.0, "angular velocity of the sphere"),
            "seed": (int, 0, "seed of the random initial vorticity"),
            "lmin": (int, 1, "lowest degree of the random initial vorticity"),
            "lmax": (int, None, "highest degree of the random initial vorticity (min(10, N-1))"),
            "slope": (float, None, "energy spectrum E_l ~ l^slope of the data (white if unset)"),
            "rms": (float, 1.0, "root-mean-square initial vorticity"),
        },
        "Zeitlin's quantized Euler equations on the (rotating) sphere, su(N)",
    ),
}

_ALIASES = {"heisenberg-chain": "spin-chain", "rigid_body": "rigid-body"}


def _solver_factory(cls: type) -> Callable[..., Any]:
    def make(rtol: float | None) -> Any:
        return cls() if rtol is None else cls(rtol=rtol)

    return make


SOLVERS: dict[str, Callable[[float | None], Any]] = {
    "fixed-point": _solver_factory(FixedPoint),
    "newton": _solver_factory(Newton),
}


def _isosyrk(stages: int) -> Callable[[Any], Method]:
    return lambda solver: IsoSyRK(stages, solver=solver)


def _composed(base: Callable[..., Method], scheme: str) -> Callable[[Any], Method]:
    return lambda solver: Composition(base(solver=solver), scheme)


METHODS: dict[str, Callable[[Any], Method]] = {
    "isomp": lambda solver: IsoMP(solver=solver),
    "spherical-midpoint": lambda solver: SphericalMidpoint(solver=solver),
    "classical-midpoint": lambda solver: ClassicalMidpoint(solver=solver),
    "rk4": lambda solver: RK4(),
    **{f"isosyrk-{s}": _isosyrk(s) for s in (1, 2, 3)},
    **{f"isomp-{scheme}": _composed(IsoMP, scheme) for scheme in SCHEMES},
    **{f"spherical-midpoint-{scheme}": _composed(SphericalMidpoint, scheme) for scheme in SCHEMES},
}

_RUN_KEYS = {"model", "params", "method", "solver", "rtol", "t0", "dt", "t1", "n_steps"}
_RUN_KEYS |= {"save_every"}


def _choice(value: Any, options: dict[str, Any], what: str) -> str:
    name = str(value)
    name = _ALIASES.get(name, name)
    if name not in options:
        raise ConfigError(f"unknown {what} {value!r} (choose from {', '.join(sorted(options))})")
    return name


def _number(value: Any, kind: type, what: str) -> Any:
    if isinstance(value, bool) or value is None:
        raise ConfigError(f"{what} must be a number, got {value!r}")
    try:
        if kind is int:
            if isinstance(value, float) and not value.is_integer():
                raise ValueError
            out: Any = int(value)
        else:
            out = float(value)
    except (TypeError, ValueError):
        raise ConfigError(
            f"{what} must be {'an integer' if kind is int else 'a number'}, got {value!r}"
        ) from None
    if kind is float and not math.isfinite(out):
        raise ConfigError(f"{what} must be finite, got {value!r}")
    return out


def normalize_config(config: dict[str, Any]) -> dict[str, Any]:
    """Check a run configuration and fill in the defaults; returns a new JSON-ready dict.

    Raises
    ------
    ConfigError
        Unknown keys, model, method, solver or parameter, or a value of the wrong type.
    """
    if not isinstance(config, dict):
        raise ConfigError("a run configuration must be a table/dictionary")
    unknown = set(config) - _RUN_KEYS
    if unknown:
        raise ConfigError(
            f"unknown option(s) {', '.join(sorted(unknown))} "
            f"(known: {', '.join(sorted(_RUN_KEYS))})"
        )
    if "model" not in config:
        raise ConfigError("the configuration names no model")
    model = _choice(config["model"], MODELS, "model")
    spec = MODELS[model]
    given = config.get("params") or {}
    if not isinstance(given, dict):
        raise ConfigError("params must be a table of model parameters")
    params: dict[str, Any] = {}
    for key, value in given.items():
        if key not in spec.params:
            known = ", ".join(spec.params) or "none"
            raise ConfigError(f"model {model!r} has no parameter {key!r} (parameters: {known})")
        kind = spec.params[key][0]
        if value is None:
            continue
        params[key] = str(value) if kind is str else _number(value, kind, f"{model} {key}")
    for key, (_kind, default, _help) in spec.params.items():
        if key not in params and default is not None:
            params[key] = default
    out: dict[str, Any] = {
        "model": model,
        "params": params,
        "method": _choice(config.get("method", "isomp"), METHODS, "method"),
        "solver": _choice(config.get("solver", "fixed-point"), SOLVERS, "solver"),
        "rtol": None if config.get("rtol") is None else _number(config["rtol"], float, "rtol"),
        "t0": _number(config.get("t0", 0.0), float, "t0"),
        "save_every": _number(config.get("save_every", 1), int, "save_every"),
    }
    if out["save_every"] < 1:
        raise ConfigError(f"save_every must be >= 1, got {out['save_every']}")
    if out["rtol"] is not None and out["rtol"] <= 0:
        raise ConfigError(f"rtol must be positive, got {out['rtol']}")
    for key, kind in (("dt", float), ("t1", float), ("n_steps", int)):
        if config.get(key) is not None:
            out[key] = _number(config[key], kind, key)
    if sum(k in out for k in ("dt", "t1", "n_steps")) != 2:
        raise ConfigError("give exactly two of dt, t1 and n_steps")
    return out


def build(config: dict[str, Any]) -> tuple[IsospectralProblem, Any, Method, dict[str, Any]]:
    """``(problem, y0, method, solve_kwargs)`` from a run configuration.

    ``solve_kwargs`` holds ``t0``, ``save_every`` and two of ``dt``, ``t1``, ``n_steps``, ready for
    ``iso.solve(problem, method, y0, **solve_kwargs)``.
    """
    cfg = normalize_config(config)
    spec = MODELS[cfg["model"]]
    problem, y0 = spec.func(**cfg["params"])
    method = METHODS[cfg["method"]](SOLVERS[cfg["solver"]](cfg["rtol"]))
    kwargs: dict[str, Any] = {
        k: cfg[k] for k in ("t0", "dt", "t1", "n_steps", "save_every") if k in cfg
    }
    return problem, np.asarray(y0), method, kwargs
