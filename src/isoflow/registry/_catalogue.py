"""The model catalogue: :class:`ModelSpec`, the built-in :data:`MODELS`, and :func:`load_model`.

A model is named by a built-in name (:data:`MODELS`, older spellings in
:data:`MODEL_ALIASES`), by the name an installed package registers under the entry-point group
:data:`ENTRY_POINT_GROUP`, or as ``"package.module:function"`` (a user's factory). Only
:func:`load_model` imports code, and only for a name the user gave; an error of the user's
code (a module that does not import, a factory that raises) is one line of
:class:`~isoflow.registry.ConfigError` naming the place in the user's code.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import keyword
import re
import traceback
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .._errors import IsoflowError
from ..problems import IsospectralProblem
from ._params import ConfigError, Param

__all__ = [
    "DENSE_MAX_N",
    "ENTRY_POINT_GROUP",
    "MHD_MAX_N",
    "MODELS",
    "MODEL_ALIASES",
    "ModelSpec",
    "check_model_name",
    "entry_points",
    "load_model",
]

#: Entry-point group under which installed packages register models by name.
ENTRY_POINT_GROUP = "isoflow.models"

#: The isoflow package: frames of its code are not the user's (:func:`_where`).
_PACKAGE_DIR = str(Path(__file__).resolve().parents[1])


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
    skip = (_PACKAGE_DIR, str(Path(importlib.__file__).parent), "<frozen ")
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


def _sphere_data_params(what: str) -> dict[str, Param]:
    """The initial data, dissipation and forcing parameters of the sphere models."""
    return {
        "seed": _seed(f"seed of the random initial {what}"),
        "lmin": Param(int, 1, f"lowest degree of the random initial {what}", low=1),
        "lmax": Param(
            int, None, f"highest degree of the random initial {what} (min(10, N-1))", low=1
        ),
        "slope": Param(float, None, "energy spectrum E_l ~ l^slope of the data (white if unset)"),
        "rms": Param(float, 1.0, f"root-mean-square initial {what}", low=0.0),
        "viscosity": Param(float, None, "viscosity nu (nu Delta)", low=0.0),
        "hyperviscosity": Param(
            float, None, "hyperviscosity nu_p, p: -nu_p (-Delta)^p, p >= 1", low=0.0, length=2
        ),
        "drag": Param(float, None, "linear drag alpha", low=0.0),
        "forcing_band": Param(
            int,
            None,
            "white-noise forcing of the degrees lf - dl .. lf + dl: lf, dl",
            low=0,
            length=2,
        ),
        "energy_rate": Param(
            float, None, "mean energy injection of the forcing band (default 1.0)", low=0.0
        ),
        "forcing_seed": Param(int, None, "seed of the forcing noise (default 0)", low=0),
    }


def _noise_seed(needed_with: str = "noise") -> Param:
    return Param(int, None, f"seed of the noise's increments (required with {needed_with})", low=0)


def _thermal() -> dict[str, Param]:
    """The stochastic Landau-Lifshitz-Gilbert parameters of the spin models."""
    return {
        "temperature": Param(float, 0.0, "temperature k_B T (needs damping > 0)", low=0.0),
        "damping": Param(float, 0.0, "Gilbert damping lambda", low=0.0),
        "noise_seed": _noise_seed("temperature > 0"),
    }


#: Largest matrix size ``n`` of a dense model from the command line (a state of 32 MiB, real).
DENSE_MAX_N = 2048
#: Largest ``N`` of MHD on the sphere from the command line: two complex fields (32 MiB) and six
#: ``N x N`` products an iteration (about 10 s an iteration on one core at this size).
MHD_MAX_N = 1024

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
                # as iso.models.toda: no seed is the state a = 0, b = 1, not a random one
                "seed": Param(
                    int,
                    None,
                    "seed of a random initial state (unset: a_i = 0, b_i = 1, "
                    "eigenvalues 2 cos(k pi / (n + 1)))",
                    low=0,
                ),
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
                **_sphere_data_params("vorticity"),
                "double_bracket": Param(
                    float, None, "selective decay: energy dissipated, Casimirs kept", low=0.0
                ),
                "noise": Param(
                    float,
                    None,
                    "transport noise on the stream functions of degrees 1, 2",
                    low=0.0,
                ),
                "noise_seed": _noise_seed(),
            },
            "Zeitlin's quantized Euler equations on the (rotating) sphere, su(N)",
            builtin=True,
            initial=("seed", "lmin", "lmax", "slope", "rms"),
        ),
        ModelSpec(
            "qg-sphere",
            "isoflow.models:qg_sphere",
            {
                "N": _size("matrix size of su(N): degrees l <= N - 1", 128, 2, DENSE_MAX_N),
                "lamb": Param(float, 0.0, "Lamb parameter F (0: Euler)", low=0.0),
                "omega": Param(float, 0.0, "angular velocity of the sphere"),
                "deformation_radius": Param(
                    float, None, "Helmholtz variant: kappa = 1/deformation_radius", low=0.0
                ),
                **_sphere_data_params("potential vorticity"),
            },
            "shallow-water quasi-geostrophic model on the rotating sphere, su(N)",
            builtin=True,
            initial=("seed", "lmin", "lmax", "slope", "rms"),
        ),
        ModelSpec(
            "mhd-sphere",
            "isoflow.models:mhd_sphere",
            {
                "N": _size("matrix size of su(N): degrees l <= N - 1", 128, 2, MHD_MAX_N),
                "omega": Param(float, 0.0, "angular velocity of the sphere"),
                "seed": _seed("seed of the random initial vorticity and current"),
                "lmin": Param(int, 1, "lowest degree of the random initial data", low=1),
                "lmax": Param(
                    int, None, "highest degree of the random initial data (min(10, N-1))", low=1
                ),
                "slope": Param(
                    float, None, "kinetic and magnetic spectra E_l ~ l^slope (white if unset)"
                ),
                "kinetic_energy": Param(float, 0.25, "initial kinetic energy", low=0.0),
                "magnetic_energy": Param(float, 0.25, "initial magnetic energy", low=0.0),
            },
            "Zeitlin's magnetohydrodynamics on the (rotating) sphere, su(N) x| su(N)*",
            builtin=True,
            initial=("seed", "lmin", "lmax", "slope", "kinetic_energy", "magnetic_energy"),
        ),
        ModelSpec(
            "heavy-top",
            "isoflow.models:heavy_top",
            {
                "top": Param(
                    str, "lagrange", "which top", choices=("lagrange", "kovalevskaya", "general")
                ),
                "inertia": Param(
                    float,
                    None,
                    "principal moments of inertia I1, I2, I3 [kg m^2]",
                    low=0.0,
                    length=3,
                ),
                "mgl": Param(
                    float, 1.0, "mass x gravity x distance of the centre of mass [N m]", low=0.0
                ),
                "M0": Param(float, None, "initial body angular momentum [kg m^2/s]", length=3),
                "Gamma0": Param(float, None, "initial upward vertical in the body frame", length=3),
            },
            "heavy top (Lagrange, Kovalevskaya or general) on se(3)* = so(3) x| R^3",
            builtin=True,
            initial=("M0", "Gamma0"),
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


def check_model_name(name: Any) -> str:
    """``name`` as a configuration records it: older spellings mapped, a user's
    ``package.module:function`` checked for its form (nothing is imported).

    Raises
    ------
    ConfigError
        Not a non-empty string, or a malformed ``package.module:function``.
    """
    if not isinstance(name, str) or not name:
        raise ConfigError(f"model must be a name (a string), got {name!r}")
    name = MODEL_ALIASES.get(name, name)
    if _is_import_spec(name) and (
        not _IMPORT_SPEC.match(name) or any(keyword.iskeyword(p) for p in re.split("[.:]", name))
    ):
        raise ConfigError(f"model {name!r}: a model of your own is named 'package.module:function'")
    return name


def entry_points() -> dict[str, importlib.metadata.EntryPoint]:
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
    name = check_model_name(name)
    if name in MODELS:
        return MODELS[name]
    if _is_import_spec(name):
        module_name, _, attr = name.partition(":")
        module = _import_module(module_name, name)
        return _spec_from(_resolve(module, attr, name), name)
    eps = entry_points()
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
