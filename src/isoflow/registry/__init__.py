"""The one name map: models, methods, solvers and experiments, and run configurations.

Everything that names a model, a method, a solver or an experiment in plain text reads this
package: ``isoflow run`` (options and TOML files), :func:`isoflow.io.resume` (the configuration
a result file stores as JSON), ``isoflow demo``, ``isoflow reproduce``, sweeps and the
experiments.

A run configuration is a flat dictionary::

    {"model": "rigid-body", "params": {"n": 10}, "method": "isomp", "solver": "fixed-point",
     "rtol": 1e-14, "anderson": 0, "t0": 0.0, "dt": 0.1, "t1": 100.0, "save_every": 10}

Spellings (one per thing, lower case with hyphens):

* **models**: the built-in ones in :data:`MODELS` (``rigid-body``, ``brockett``, ``toda``,
  ``spin-chain``, ``hyperbolic-vortices``, ``spin-lattice``, ``euler-sphere``, ``mhd-sphere``,
  ``heavy-top``); a model registered by an installed
  package under the entry-point group ``isoflow.models``; or your own factory named
  ``"package.module:function"`` (a function returning ``(problem, initial_state)``, its keyword
  arguments from ``params``).
* **methods** (:data:`METHODS`): ``isomp``, ``isomp-cayley``, ``spherical-midpoint``,
  ``classical-midpoint``, ``stochastic-isomp``, ``stochastic-isomp-cayley``, ``stochastic-heun``,
  ``rk4``, ``isosyrk-1`` .. ``isosyrk-3`` and the compositions ``<base>-<scheme>`` (e.g.
  ``isomp-suzuki-4``, ``spherical-midpoint-kahan-li-8``).
* **solvers** (:data:`SOLVERS`): ``fixed-point`` (with ``anderson = m`` for Anderson mixing of
  the last ``m`` iterates, ``m`` at most :data:`ANDERSON_MAX`), ``newton``, ``newton-krylov``.
  Explicit methods (``rk4``) take none.
* **experiments** (:data:`EXPERIMENTS`): the paper's figures, see :mod:`isoflow.experiments`.

Nothing here imports code on its own. A configuration read from a file that names a model
which is not built in is refused by :func:`build` unless the caller hands over that model
(:func:`load_model`, what ``isoflow run --resume FILE --model ...`` does), and then it is
checked against what the file recorded (:func:`isoflow.io.rebuild.check_recorded_model`).

One concern per module, every name re-exported here:

* ``_params``: :class:`Param`, the checking of values, :func:`parse_param`,
  :class:`ConfigError`;
* ``_catalogue``: :class:`ModelSpec`, :data:`MODELS`, :data:`MODEL_ALIASES`,
  :func:`load_model` (entry points, the one-line errors of a user's model code),
  :func:`check_model_name`;
* ``_methods``: :class:`SolverSpec`, :data:`SOLVERS`, :class:`MethodSpec`, :data:`METHODS`,
  :func:`make_solver`, :func:`make_method`;
* ``_experiments``: :data:`EXPERIMENTS`, :func:`get_experiment`;
* ``_config``: :func:`normalize_config`, :func:`config_from_toml`, :func:`read_toml`,
  :func:`layered_config` (a TOML file overridden by command-line options), :func:`build`;
* ``_listing``: :func:`describe` (``isoflow list``).
"""

from __future__ import annotations

from ._catalogue import (
    DENSE_MAX_N,
    ENTRY_POINT_GROUP,
    MODEL_ALIASES,
    MODELS,
    ModelSpec,
    check_model_name,
    load_model,
)
from ._config import (
    RUN_OPTIONS,
    build,
    config_from_toml,
    layered_config,
    normalize_config,
    read_toml,
)
from ._experiments import EXPERIMENTS, get_experiment
from ._listing import describe
from ._methods import (
    ANDERSON_MAX,
    METHODS,
    SOLVERS,
    MethodSpec,
    SolverSpec,
    make_method,
    make_solver,
    split_method,
)
from ._params import ConfigError, Param, parse_param, parse_params

__all__ = [
    "ANDERSON_MAX",
    "DENSE_MAX_N",
    "ENTRY_POINT_GROUP",
    "EXPERIMENTS",
    "METHODS",
    "MODELS",
    "MODEL_ALIASES",
    "RUN_OPTIONS",
    "SOLVERS",
    "ConfigError",
    "MethodSpec",
    "ModelSpec",
    "Param",
    "SolverSpec",
    "build",
    "check_model_name",
    "config_from_toml",
    "describe",
    "get_experiment",
    "layered_config",
    "load_model",
    "make_method",
    "make_solver",
    "normalize_config",
    "parse_param",
    "parse_params",
    "read_toml",
    "split_method",
]
