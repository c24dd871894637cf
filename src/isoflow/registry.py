"""The one name map: models, methods, solvers and experiments, and run configurations.

Everything that names a model, a method, a solver or an experiment in plain text reads this
module: ``isoflow run`` (options and TOML files), :func:`isoflow.io.resume` (the configuration
a result file stores as JSON), ``isoflow demo``, ``isoflow reproduce`` and the experiments.

A run configuration is a flat dictionary::

    {"model": "rigid-body", "params": {"n": 10}, "method": "isomp", "solver": "fixed-point",
     "rtol": 1e-14, "anderson": 0, "t0": 0.0, "dt": 0.1, "t1": 100.0, "save_every": 10}

Spellings (one per thing, lower case with hyphens):

* **models**: the built-in ones in :data:`MODELS` (``rigid-body``, ``brockett``, ``toda``,
  ``spin-chain``, ``hyperbolic-vortices``, ``euler-sphere``); a model registered by an installed
  package under the entry-point group ``isoflow.models``; or your own factory named
  ``"package.module:function"`` (a function returning ``(problem, initial_state)``, its keyword
  arguments from ``params``).
* **methods** (:data:`METHODS`): ``isomp``, ``spherical-midpoint``, ``classical-midpoint``,
  ``stochastic-isomp``, ``rk4``, ``isosyrk-1`` .. ``isosyrk-3`` and the compositions
  ``<base>-<scheme>`` (e.g. ``isomp-suzuki-4``, ``spherical-midpoint-kahan-li-8``).
* **solvers** (:data:`SOLVERS`): ``fixed-point`` (with ``anderson = m`` for Anderson mixing of
  the last ``m`` iterates), ``newton``, ``newton-krylov``. Explicit methods (``rk4``) take none.
* **experiments** (:data:`EXPERIMENTS`): the paper's figures, see :mod:`isoflow.experiments`.

The rule "two of ``t1``, ``dt``, ``n_steps``" is :func:`isoflow._solve.time_grid`'s; this
module only calls it.

Nothing here imports code on its own. A configuration read from a file that names a model
which is not built in is refused by :func:`build` unless the caller hands over that model
(:func:`load_model`, what ``isoflow run --resume FILE --model ...`` does), and then it is
checked against what the file recorded (:func:`check_recorded_model`).
"""

from __future__ import annotations

import importlib
import importlib.metadata
import keyword
import math
import re
import tomllib
import traceback
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ._errors import IsoflowError
from ._solve import time_grid
from .methods import (
    RK4,
    ClassicalMidpoint,
    Composition,
    IsoMP,
    IsoSyRK,
    Method,
    SphericalMidpoint,
    StochasticIsoMP,
)
from .methods.composition import SCHEMES
from .nonlinear import FixedPoint, Newton, NonlinearSolver
from .problems import IsospectralProblem

__all__ = [
    "ENTRY_POINT_GROUP",
    "EXPERIMENTS",
    "METHODS",
    "MODELS",
    "SOLVERS",
    "ConfigError",
    "MethodSpec",
    "ModelSpec",
    "Param",
    "SolverSpec",
    "build",
    "check_recorded_model",
    "check_recorded_state",
    "config_from_toml",
    "describe",
    "get_experiment",
    "load_model",
    "make_method",
    "make_solver",
    "normalize_config",
    "parse_param",
    "read_toml",
]

#: Entry-point group under which installed packages register models by name.
ENTRY_POINT_GROUP = "isoflow.models"


class ConfigError(IsoflowError, ValueError):
    """A run configuration names an unknown model/method/option or has a bad value."""


# ---- parameters --------------------------------------------------------------------------------

_KIND_WORDS = {int: "an integer", float: "a number", str: "a string", bool: "true or false"}


@dataclass(frozen=True)
class Param:
    """A model parameter settable from the command line and from TOML.

    Attributes
    ----------
    kind : type
        ``int``, ``float``, ``str`` or ``bool`` (of each entry, with ``length``).
    default : object
        The value used when the parameter is not given; ``None`` leaves it to the model
        function's own default (the parameter is then not recorded).
    help : str
        One line for ``isoflow run --help`` and ``isoflow list models``.
    low, high : float, optional
        Inclusive bounds (of each entry). ``high`` on a size keeps a typo (``n = 100000``) from
        asking for gigabytes before anything runs; a larger system is a job for the Python API.
    choices : tuple, optional
        The allowed values.
    length : int, optional
        The parameter is a list of this many entries (``[16, 16]`` in TOML, ``16,16`` on the
        command line); the model function gets a tuple.
    """

    kind: type
    default: Any
    help: str
    low: float | None = None
    high: float | None = None
    choices: tuple[Any, ...] | None = None
    length: int | None = None

    def check(self, value: Any, what: str) -> Any:
        """``value`` (a TOML/JSON value) checked against the kind, bounds and choices."""
        if self.length is None:
            return self._check_one(value, what)
        if not isinstance(value, list | tuple) or len(value) != self.length:
            raise ConfigError(
                f"{what} must be a list of {self.length} {self.kind.__name__} values, got {value!r}"
            )
        return [self._check_one(v, what) for v in value]

    def _check_one(self, value: Any, what: str) -> Any:
        kind = self.kind
        if kind is bool:
            ok = isinstance(value, bool | np.bool_)
            out: Any = bool(value) if ok else None
        elif kind is int:
            ok = isinstance(value, int | np.integer) and not isinstance(value, bool | np.bool_)
            out = int(value) if ok else None
        elif kind is float:
            ok = isinstance(value, int | float | np.integer | np.floating) and not isinstance(
                value, bool | np.bool_
            )
            out = float(value) if ok else None
            if ok and not math.isfinite(out):
                raise ConfigError(f"{what} must be finite, got {value!r}")
        else:
            ok = isinstance(value, str)
            out = value if ok else None
        if not ok:
            raise ConfigError(f"{what} must be {_KIND_WORDS[kind]}, got {value!r}")
        if self.choices is not None and out not in self.choices:
            raise ConfigError(
                f"{what} must be one of {', '.join(map(repr, self.choices))}, got {value!r}"
            )
        if self.low is not None and out < self.low:
            raise ConfigError(f"{what} must be >= {self.low:g}, got {value!r}")
        if self.high is not None and out > self.high:
            raise ConfigError(
                f"{what} must be <= {self.high:g}, got {value!r} (a size bound of the command "
                "line and of configuration files; build larger systems from Python)"
            )
        return out

    def parse(self, text: str, what: str) -> Any:
        """The value of a command-line word ``text`` (then :meth:`check`-ed)."""
        if self.length is not None:
            body = text.strip()
            if body.startswith("[") or body.endswith("]"):
                body = body.removeprefix("[").removesuffix("]")
                if not (text.strip().startswith("[") and text.strip().endswith("]")):
                    body = ""  # unbalanced brackets
            words = [w.strip() for w in body.split(",")]
            if "" in words:
                example = self.typed(
                    self.default if self.default is not None else [self.kind(1)] * self.length
                )
                raise ConfigError(
                    f"{what} must be a list of {self.length} {self.kind.__name__} values "
                    f"written like {example}, got {text!r}"
                )
            return self.check([self._word(w) for w in words], what)
        return self.check(self._word(text), what)

    def _word(self, text: str) -> Any:
        if self.kind is str:
            return text
        try:
            if self.kind is int:
                return int(text)
            if self.kind is float:
                return float(text)
        except ValueError:
            return text  # reported by check() with the word as given
        if text.lower() in ("true", "false"):
            return text.lower() == "true"
        return text

    def value(self, checked: Any) -> Any:
        """What the model function gets for a :meth:`check`-ed value (a tuple for lists)."""
        return tuple(checked) if self.length is not None else checked

    def kind_text(self) -> str:
        """The kind as ``isoflow list`` shows it: ``int``, or ``2-vector of int``."""
        kind = self.kind.__name__
        return kind if self.length is None else f"{self.length}-vector of {kind}"

    def typed(self, value: Any) -> str:
        """``value`` as it is typed on the command line: ``16,16``, ``0.5``, ``curve``."""
        if isinstance(value, list | tuple):
            return ",".join(self.typed(v) for v in value)
        if isinstance(value, bool):
            return "true" if value else "false"
        if self.kind is int and isinstance(value, int | float) and float(value).is_integer():
            return str(int(value))
        if isinstance(value, float):
            return f"{value:g}"
        return str(value)

    def describe(self, name: str) -> str:
        """One line for ``isoflow list``: name, kind, default, help and upper bound."""
        default = "" if self.default is None else f", default {self.typed(self.default)}"
        bound = "" if self.high is None else f" [at most {self.typed(self.high)}]"
        return f"{name} ({self.kind_text()}{default}): {self.help}{bound}"


# ---- models ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ModelSpec:
    """A model: a factory returning ``(problem, initial_state)`` and its parameters.

    Attributes
    ----------
    name : str
        The spelling recorded in configurations and result files: a built-in or entry-point
        name, or ``"package.module:function"``.
    factory : str or callable
        ``factory(**params) -> (IsospectralProblem, y0)``, or ``"module:attribute"`` naming it
        (imported on first use, so that listing models imports nothing).
    params : mapping or None
        Parameter name -> :class:`Param`. ``None``: not declared (a user's plain factory); any
        TOML value is passed through and the factory checks its own arguments.
    description : str
        One line.
    builtin : bool
        Part of isoflow. Only built-in models are rebuilt from a file's configuration alone.
    initial : tuple of str
        The parameters that only set the initial state (seeds, amplitudes of random data):
        members of a sweep that differ only in them share ``B``, ``H``, the invariants and the
        kernel, so they run as one ensemble (:mod:`isoflow.sweep`).

    A package registers a model by pointing an entry point of the group ``isoflow.models`` at
    such an object (typed parameters, bounds, help) or at a plain factory function.
    """

    name: str
    factory: str | Callable[..., Any]
    params: Mapping[str, Param] | None = None
    description: str = ""
    builtin: bool = False
    initial: tuple[str, ...] = ()

    def function(self) -> Callable[..., Any]:
        """The factory function (imported if given by name)."""
        if not isinstance(self.factory, str):
            return self.factory
        module, _, attr = self.factory.partition(":")
        if self.builtin:
            return _resolve(importlib.import_module(module), attr, self.factory)
        return _resolve(_import_module(module, self.name), attr, self.factory)

    def make(self, params: Mapping[str, Any]) -> tuple[IsospectralProblem, Any]:
        """``(problem, y0)`` from the factory with keyword arguments ``params``.

        Raises
        ------
        ConfigError
            Arguments the factory does not take; for a model that is not built in, any error
            of the factory that is not an isoflow error, in one line with its place in the
            user's code.
        """
        if self.params is not None:
            params = {
                k: self.params[k].value(v) if k in self.params else v for k, v in params.items()
            }
        factory = self.function()
        try:
            out = factory(**params)
        except IsoflowError:
            raise
        except TypeError as exc:
            raise ConfigError(f"model {self.name!r}: {exc}") from exc
        except Exception as exc:
            if self.builtin:
                raise
            raise _user_code_error(self.name, "the factory", exc) from exc
        if (
            not isinstance(out, tuple)
            or len(out) != 2
            or not isinstance(out[0], IsospectralProblem)
        ):
            raise ConfigError(
                f"model {self.name!r} must return (problem, initial_state) with an "
                f"iso.IsospectralProblem, got {_describe(out)}"
            )
        return out[0], out[1]


def _public_name(exc: BaseException) -> str:
    """The exception's class name, or its nearest public base (``MemoryError`` for NumPy's
    ``_ArrayMemoryError``)."""
    for cls in type(exc).__mro__:
        if not cls.__name__.startswith("_"):
            return cls.__name__
    return type(exc).__name__  # pragma: no cover - object is public


def _where(exc: BaseException) -> str:
    """``file:line`` in the user's code where ``exc`` arose: for a ``SyntaxError`` the line
    that does not parse, else the deepest line of the first file outside isoflow and the
    import machinery that the traceback passes through."""
    if isinstance(exc, SyntaxError) and exc.filename:
        return f"{exc.filename}:{exc.lineno}"
    skip = (str(Path(__file__).resolve().parent), str(Path(importlib.__file__).parent), "<frozen ")
    frames = [f for f in traceback.extract_tb(exc.__traceback__) if not f.filename.startswith(skip)]
    if not frames:
        return ""
    user = [f for f in frames if f.filename == frames[0].filename]
    return f"{user[-1].filename}:{user[-1].lineno}"


def _user_code_error(name: str, doing: str, exc: BaseException) -> ConfigError:
    """One line for an error raised by a user's model code (a module that does not import, a
    factory that raises): what was being done, the exception and where in the user's code."""
    where = _where(exc)
    text = " ".join(str(exc).split()) if not isinstance(exc, SyntaxError) else exc.msg
    return ConfigError(
        f"model {name!r}: {doing} raised {_public_name(exc)}"
        + (f" at {where}" if where else "")
        + (f": {text}" if text else "")
    )


def _import_module(module_name: str, name: str) -> Any:
    """Import the module of a user's model, any failure a one-line :class:`ConfigError`."""
    try:
        return importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        if exc.name and (module_name == exc.name or module_name.startswith(exc.name + ".")):
            raise ConfigError(
                f"model {name!r}: cannot import {module_name!r} ({exc}); is it installed or "
                "on PYTHONPATH?"
            ) from exc
        raise _user_code_error(name, f"importing {module_name!r}", exc) from exc
    except Exception as exc:
        raise _user_code_error(name, f"importing {module_name!r}", exc) from exc


def _describe(obj: Any) -> str:
    if isinstance(obj, tuple):
        return "a tuple of " + ", ".join(type(x).__name__ for x in obj)
    return type(obj).__name__


def _size(help_: str, default: int, low: int, high: int) -> Param:
    return Param(int, default, help_, low=low, high=high)


def _seed(help_: str = "seed of the random initial data") -> Param:
    return Param(int, 0, help_, low=0)


def _noise_seed() -> Param:
    return Param(int, None, "seed of the noise's increments (required with noise)", low=0)


def _thermal() -> dict[str, Param]:
    """The stochastic Landau-Lifshitz-Gilbert parameters of the spin models."""
    return {
        "temperature": Param(float, 0.0, "temperature k_B T (needs damping > 0)", low=0.0),
        "damping": Param(float, 0.0, "Gilbert damping lambda", low=0.0),
        "noise_seed": _noise_seed(),
    }


#: Largest matrix size ``n`` of a dense model from the command line (a state of 32 MiB, real).
DENSE_MAX_N = 2048

#: The built-in models: name -> :class:`ModelSpec`.
MODELS: dict[str, ModelSpec] = {
    spec.name: spec
    for spec in (
        ModelSpec(
            "rigid-body",
            "isoflow.models:rigid_body",
            {
                "n": _size("matrix size of so(n)", 10, 2, DENSE_MAX_N),
                "noise": Param(
                    float, None, "transport noise amplitude (one field per basis element)", low=0.0
                ),
                "noise_seed": _noise_seed(),
            },
            "generalized rigid body on so(n), the paper's inertia and W0 (Sec. 3.1)",
            builtin=True,
        ),
        ModelSpec(
            "brockett",
            "isoflow.models:brockett",
            {
                "n": _size("matrix size of herm(n)", 10, 2, DENSE_MAX_N),
                "seed": _seed("seed of the random Hermitian W0"),
                "scale": Param(float, None, "norm scale of W0 (default: the model's)", low=0.0),
            },
            "Brockett double bracket flow, N = diag(1..n) (Sec. 3.2)",
            builtin=True,
            initial=("seed", "scale"),
        ),
        ModelSpec(
            "toda",
            "isoflow.models:toda",
            {
                "n": _size("number of particles", 12, 2, DENSE_MAX_N),
                "seed": _seed(),
            },
            "non-periodic Toda lattice on sym(n), Flaschka form",
            builtin=True,
            initial=("seed",),
        ),
        ModelSpec(
            "spin-chain",
            "isoflow.models:heisenberg_chain",
            {
                "N": _size("number of spins", 100, 2, 10**7),
                "initial": Param(
                    str, "curve", "'curve' (the paper's) or 'random'", choices=("curve", "random")
                ),
                "seed": _seed("seed for initial = 'random'"),
                **_thermal(),
            },
            "periodic Heisenberg spin chain on (R^3, x)^N (Sec. 3.3)",
            builtin=True,
            initial=("initial", "seed"),
        ),
        ModelSpec(
            "hyperbolic-vortices",
            "isoflow.models:hyperbolic_vortices",
            {"config": Param(int, 1, "the paper's initial configuration, 1 or 2", choices=(1, 2))},
            "three point vortices on the hyperbolic plane, sl(2,R)^3 (Sec. 3.4)",
            builtin=True,
        ),
        ModelSpec(
            "spin-lattice",
            "isoflow.models:spin_lattice",
            {
                "shape": Param(int, [16, 16], "lattice size L1, L2", low=3, high=3000, length=2),
                "J": Param(float, 1.0, "exchange coupling (> 0 antiferromagnetic)"),
                "anisotropy": Param(float, 0.0, "XXZ anisotropy: z coupling J (1 + anisotropy)"),
                "field": Param(float, [0.0, 0.0, 0.0], "Zeeman field h", length=3),
                "initial": Param(
                    str, "random", "'random' or 'ferro' (a spin wave)", choices=("random", "ferro")
                ),
                "seed": _seed(),
                **_thermal(),
            },
            "classical Heisenberg/XXZ spins with a Zeeman field on a periodic square lattice",
            builtin=True,
            initial=("initial", "seed"),
        ),
        ModelSpec(
            "euler-sphere",
            "isoflow.models:euler_sphere",
            {
                "N": _size("matrix size of su(N): degrees l <= N - 1", 128, 2, DENSE_MAX_N),
                "omega": Param(float, 0.0, "angular velocity of the sphere"),
                "seed": _seed("seed of the random initial vorticity"),
                "lmin": Param(int, 1, "lowest degree of the random initial vorticity", low=1),
                "lmax": Param(
                    int,
                    None,
                    "highest degree of the random initial vorticity (min(10, N-1))",
                    low=1,
                ),
                "slope": Param(
                    float, None, "energy spectrum E_l ~ l^slope of the data (white if unset)"
                ),
                "rms": Param(float, 1.0, "root-mean-square initial vorticity", low=0.0),
            },
            "Zeitlin's quantized Euler equations on the (rotating) sphere, su(N)",
            builtin=True,
            initial=("seed", "lmin", "lmax", "slope", "rms"),
        ),
    )
}

#: Older spellings still read (from configuration files) and written as the name they map to.
MODEL_ALIASES = {"heisenberg-chain": "spin-chain", "rigid_body": "rigid-body"}

_IMPORT_SPEC = re.compile(r"^[A-Za-z_]\w*(\.[A-Za-z_]\w*)*:[A-Za-z_]\w*(\.[A-Za-z_]\w*)*$")


def _resolve(module: Any, attr: str, spec: str) -> Any:
    obj = module
    for part in attr.split("."):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            raise ConfigError(
                f"model {spec!r}: module {module.__name__!r} has no attribute {attr!r}"
            ) from None
    return obj


def _is_import_spec(name: str) -> bool:
    return ":" in name


def _check_model_name(name: Any) -> str:
    if not isinstance(name, str) or not name:
        raise ConfigError(f"model must be a name (a string), got {name!r}")
    name = MODEL_ALIASES.get(name, name)
    if _is_import_spec(name) and (
        not _IMPORT_SPEC.match(name) or any(keyword.iskeyword(p) for p in re.split("[.:]", name))
    ):
        raise ConfigError(f"model {name!r}: a model of your own is named 'package.module:function'")
    return name


def _entry_points() -> dict[str, importlib.metadata.EntryPoint]:
    """Models registered by installed packages (reads package metadata, imports nothing)."""
    return {ep.name: ep for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP)}


def _spec_from(obj: Any, name: str) -> ModelSpec:
    """A :class:`ModelSpec` from what an entry point or an import path names."""
    if isinstance(obj, ModelSpec):
        return ModelSpec(
            name, obj.factory, obj.params, obj.description, builtin=False, initial=obj.initial
        )
    if callable(obj):
        doc = (getattr(obj, "__doc__", None) or "").strip().splitlines()
        return ModelSpec(name, obj, None, doc[0] if doc else "", builtin=False)
    raise ConfigError(
        f"model {name!r} names a {type(obj).__name__}, not a function returning "
        "(problem, initial_state) or an isoflow.registry.ModelSpec"
    )


def load_model(name: str) -> ModelSpec:
    """The model called ``name``, importing a user's module if the name says so.

    Parameters
    ----------
    name : str
        A built-in model (:data:`MODELS`), a model registered under the entry-point group
        ``isoflow.models`` (its package is imported), or ``"package.module:function"`` (the
        module is imported: call this only for a name the user gave, never for one read from a
        file).

    Raises
    ------
    ConfigError
        Unknown name, a module that does not import, a missing attribute.
    """
    name = _check_model_name(name)
    if name in MODELS:
        return MODELS[name]
    if _is_import_spec(name):
        module_name, _, attr = name.partition(":")
        module = _import_module(module_name, name)
        return _spec_from(_resolve(module, attr, name), name)
    eps = _entry_points()
    if name in eps:
        try:
            obj = eps[name].load()
        except ImportError as exc:
            raise ConfigError(
                f"model {name!r} (entry point {eps[name].value!r}) does not load: {exc}"
            ) from exc
        except Exception as exc:
            raise _user_code_error(name, f"loading entry point {eps[name].value!r}", exc) from exc
        return _spec_from(obj, name)
    known = sorted(MODELS) + sorted(eps)
    raise ConfigError(
        f"unknown model {name!r} (choose from {', '.join(known)}, or name your own "
        "factory as package.module:function)"
    )


# ---- solvers and methods -----------------------------------------------------------------------


@dataclass(frozen=True)
class SolverSpec:
    """A nonlinear solver for implicit methods: ``make(rtol, anderson)``."""

    name: str
    make: Callable[[float | None, int], NonlinearSolver]
    description: str
    anderson: bool = False


def _fixed_point(rtol: float | None, anderson: int) -> NonlinearSolver:
    kw: dict[str, Any] = {} if rtol is None else {"rtol": rtol}
    return FixedPoint(anderson=anderson, **kw)


def _newton(jacobian: str) -> Callable[[float | None, int], NonlinearSolver]:
    def make(rtol: float | None, anderson: int) -> NonlinearSolver:
        kw: dict[str, Any] = {} if rtol is None else {"rtol": rtol}
        return Newton(jacobian=jacobian, **kw)  # type: ignore[arg-type]

    return make


#: Nonlinear solvers: name -> :class:`SolverSpec`.
SOLVERS: dict[str, SolverSpec] = {
    "fixed-point": SolverSpec(
        "fixed-point",
        _fixed_point,
        "fixed-point iteration (the default; anderson = m mixes the last m iterates)",
        anderson=True,
    ),
    "newton": SolverSpec("newton", _newton("dense"), "Newton, dense Jacobian (small spaces)"),
    "newton-krylov": SolverSpec(
        "newton-krylov", _newton("krylov"), "Newton-GMRES, matrix-free (large spaces)"
    ),
}

#: Largest Anderson memory (as :class:`isoflow.FixedPoint` accepts).
ANDERSON_MAX = 8


@dataclass(frozen=True)
class MethodSpec:
    """A time-stepping method: ``make(solver)``; ``implicit`` methods take a solver."""

    name: str
    make: Callable[[NonlinearSolver | None], Method]
    description: str
    implicit: bool = True


def _composed(base: Callable[..., Method], scheme: str) -> Callable[[Any], Method]:
    return lambda solver: Composition(base(solver=solver), scheme)


def _plain(cls: Callable[..., Method]) -> Callable[[Any], Method]:
    return lambda solver: cls(solver=solver)


def _isosyrk(stages: int) -> Callable[[Any], Method]:
    return lambda solver: IsoSyRK(stages, solver=solver)


_BASES: dict[str, tuple[Callable[..., Method], str]] = {
    "isomp": (IsoMP, "isospectral minimal midpoint (the paper's method)"),
    "spherical-midpoint": (SphericalMidpoint, "spherical midpoint, (R^3, x)^N only"),
    "classical-midpoint": (ClassicalMidpoint, "classical implicit midpoint (not isospectral)"),
}

#: Methods: name -> :class:`MethodSpec`.
METHODS: dict[str, MethodSpec] = {
    **{name: MethodSpec(name, _plain(cls), text) for name, (cls, text) in _BASES.items()},
    "rk4": MethodSpec("rk4", lambda solver: RK4(), "classical RK4 (explicit)", implicit=False),
    "stochastic-isomp": MethodSpec(
        "stochastic-isomp",
        _plain(StochasticIsoMP),
        "stochastic isospectral midpoint (models with noise or a temperature)",
    ),
    **{
        f"isosyrk-{s}": MethodSpec(
            f"isosyrk-{s}",
            _isosyrk(s),
            f"isospectral symplectic Gauss RK, {s} stage{'s' if s > 1 else ''}, order {2 * s}",
        )
        for s in (1, 2, 3)
    },
    **{
        f"{base}-{scheme}": MethodSpec(
            f"{base}-{scheme}",
            _composed(cls, scheme),
            f"{base} composed by {scheme} (order {SCHEMES[scheme][1]})",
        )
        for base, (cls, _text) in _BASES.items()
        for scheme in SCHEMES
    },
}


def make_solver(name: str = "fixed-point", *, rtol: float | None = None, anderson: int = 0):
    """The nonlinear solver called ``name`` (:data:`SOLVERS`)."""
    spec = SOLVERS[_choice(name, SOLVERS, "solver")]
    if anderson and not spec.anderson:
        raise ConfigError(f"anderson mixing is an option of the fixed-point solver, not {name!r}")
    return spec.make(rtol, anderson)


def make_method(name: str, solver: NonlinearSolver | None = None) -> Method:
    """The method called ``name`` (:data:`METHODS`) with ``solver`` (default: fixed point)."""
    spec = METHODS[_choice(name, METHODS, "method")]
    if not spec.implicit:
        if solver is not None:
            raise ConfigError(f"method {name!r} is explicit: it takes no nonlinear solver")
        return spec.make(None)
    return spec.make(solver if solver is not None else FixedPoint())


# ---- experiments -------------------------------------------------------------------------------

#: The paper's experiments: name -> ``"module:attribute"`` of its
#: :class:`isoflow.experiments.Experiment` (imported by :func:`get_experiment`).
EXPERIMENTS: dict[str, str] = {
    name: f"isoflow.experiments.{name.replace('-', '_')}:{name.replace('-', '_')}"
    for name in (
        "rigid-body",
        "brockett",
        "spin-chain-cost",
        "spin-chain-energy",
        "spin-chain-error",
        "vortices-trajectories",
        "vortices-invariants",
        "euler-sphere",
        "work-precision",
    )
}


def get_experiment(name: str) -> Any:
    """The :class:`isoflow.experiments.Experiment` called ``name``."""
    module, _, attr = EXPERIMENTS[_choice(name, EXPERIMENTS, "experiment")].partition(":")
    return getattr(importlib.import_module(module), attr)


# ---- configurations ----------------------------------------------------------------------------

_RUN_KEYS = frozenset(
    {"model", "params", "method", "solver", "rtol", "anderson", "t0", "dt", "t1", "n_steps"}
    | {"save_every"}
)


def _choice(value: Any, options: Mapping[str, Any], what: str) -> str:
    if not isinstance(value, str):
        raise ConfigError(f"{what} must be a name (a string), got {value!r}")
    if value not in options:
        hint = ""
        near = value.strip().lower().replace("_", "-").replace(" ", "-")
        if near in options:
            hint = f"; write {near!r}"
        raise ConfigError(f"unknown {what} {value!r}{hint} (choose from {', '.join(options)})")
    return value


def _names(options: Mapping[str, Any]) -> str:
    """The names of ``options``, the compositions of :data:`METHODS` abbreviated."""
    if options is METHODS:
        plain = [m for m in METHODS if not any(m.endswith(f"-{s}") for s in SCHEMES)]
        return (
            ", ".join(plain) + ", and <base>-<scheme> for base isomp, spherical-midpoint or "
            f"classical-midpoint and scheme {', '.join(SCHEMES)}"
        )
    return ", ".join(options)


def _number(value: Any, kind: type, what: str) -> Any:
    return Param(kind, None, "").check(value, what)


def _json_value(value: Any, what: str) -> Any:
    """A parameter of an undeclared model: a TOML/JSON value (recorded in result files)."""
    if isinstance(value, bool | str) or value is None:
        return value
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        if not math.isfinite(value):
            raise ConfigError(f"{what} must be finite, got {value!r}")
        return float(value)
    if isinstance(value, list | tuple):
        return [_json_value(v, f"{what}[{i}]") for i, v in enumerate(value)]
    if isinstance(value, dict):
        for k in value:
            if not isinstance(k, str):
                raise ConfigError(f"{what}: table keys must be strings, got {k!r}")
        return {k: _json_value(v, f"{what}.{k}") for k, v in value.items()}
    raise ConfigError(
        f"{what} must be a number, string, boolean, array or table, got {type(value).__name__}"
    )


def parse_param(spec: ModelSpec, key: str, text: str) -> Any:
    """The value of model parameter ``key`` given as command-line text.

    A declared parameter is converted to its kind (``"ten"`` for an integer is an error); for a
    model without declared parameters the text is read as a TOML value (``3`` an integer,
    ``0.5`` a float, ``true`` a boolean, ``[1, 2]`` an array), or kept as a string; text that
    starts like a TOML array, table or quoted string but does not parse is an error.
    """
    if spec.params is not None:
        if key not in spec.params:
            known = ", ".join(spec.params) or "none"
            raise ConfigError(f"model {spec.name!r} has no parameter {key!r} (parameters: {known})")
        return spec.params[key].parse(text, f"{spec.name} {key}")
    import tomllib

    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError as exc:
        if text.strip()[:1] in ("[", "{", '"', "'"):  # meant as a TOML list, table or string
            raise ConfigError(
                f"--param {key}: {text!r} is not a TOML value ({' '.join(str(exc).split())}); "
                'write a list as [1, 2], a table as {a = 1}, a string as "text"'
            ) from None
        return text  # a plain word: the string itself


def normalize_config(config: Mapping[str, Any], *, model: ModelSpec | None = None) -> dict:
    """Check a run configuration and fill in the defaults; returns a new JSON-ready dict.

    Parameters
    ----------
    config : mapping
        See the module docstring. Values must have their types (``dt = 0.1``, not ``"0.1"``).
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
    name = _check_model_name(config["model"])
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
        params = {str(k): _json_value(v, f"{name} {k}") for k, v in given.items()}

    method = _choice(config.get("method", "isomp"), METHODS, "method")
    out: dict[str, Any] = {"model": name, "params": params, "method": method}
    if METHODS[method].implicit:
        solver = _choice(config.get("solver", "fixed-point"), SOLVERS, "solver")
        rtol = config.get("rtol")
        if rtol is not None:
            rtol = _number(rtol, float, "rtol")
            if rtol <= 0:
                raise ConfigError(f"rtol must be positive, got {rtol!r}")
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

    Raises
    ------
    ConfigError
        ``out`` that is not a string (the rest is checked by :func:`normalize_config`).
    """
    cfg = dict(table)
    out = cfg.pop("out", None)
    if out is not None and not (isinstance(out, str) and out):
        raise ConfigError(f"out must be a file name (a string), got {out!r}")
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
        A run configuration (checked with :func:`normalize_config`).
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
                "iso.io.resume(path, problem=..., method=...))"
            )
        model = MODELS[cfg["model"]]
    problem, y0 = model.make(cfg["params"])
    if METHODS[cfg["method"]].implicit:
        solver: NonlinearSolver | None = make_solver(
            cfg["solver"], rtol=cfg["rtol"], anderson=cfg.get("anderson", 0)
        )
    else:
        solver = None
    method = make_method(cfg["method"], solver)
    kwargs: dict[str, Any] = {
        k: cfg[k] for k in ("t0", "dt", "t1", "n_steps", "save_every") if k in cfg
    }
    return problem, np.asarray(y0), method, kwargs


def check_recorded_model(
    recorded: Mapping[str, Any], model: ModelSpec, params: Mapping[str, Any] | None = None
) -> dict[str, Any]:
    """Check that ``model`` (named again by the user) is the model a result file recorded.

    Parameters
    ----------
    recorded : mapping
        The configuration stored in the file.
    model : ModelSpec
        The model the user named (:func:`load_model`).
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
    name = _check_model_name(recorded.get("model")) if "model" in recorded else None
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
            if again.get(key) != cfg["params"].get(key):
                raise ConfigError(
                    f"parameter {key} = {again.get(key)!r} differs from the run's "
                    f"{key} = {cfg['params'].get(key)!r} recorded in the file"
                )
    return cfg


def check_recorded_state(meta: Mapping[str, Any], problem: IsospectralProblem, y0: Any) -> None:
    """Check that a rebuilt model has the space and state shape a result file recorded.

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


def describe(kind: str) -> list[tuple[str, str, list[str]]]:
    """``(name, description, parameter lines)`` of every model/method/solver/experiment."""
    if kind == "models":
        rows = []
        for spec in MODELS.values():
            lines = [p.describe(k) for k, p in (spec.params or {}).items()]
            rows.append((spec.name, spec.description, lines))
        for name, ep in sorted(_entry_points().items()):
            rows.append((name, f"registered by an installed package ({ep.value})", []))
        return rows
    if kind == "methods":
        return [(m.name, m.description, []) for m in METHODS.values()]
    if kind == "solvers":
        return [(s.name, s.description, []) for s in SOLVERS.values()]
    if kind == "experiments":
        return [(name, get_experiment(name).description, []) for name in EXPERIMENTS]
    raise ConfigError(f"nothing to list called {kind!r}")
