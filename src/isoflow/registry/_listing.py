"""What ``isoflow list`` shows: :func:`describe`."""

from __future__ import annotations

from ._catalogue import MODELS, entry_points
from ._experiments import EXPERIMENTS, get_experiment
from ._methods import METHODS, SOLVERS
from ._params import ConfigError

__all__ = ["describe"]


def describe(kind: str) -> list[tuple[str, str, list[str]]]:
    """``(name, description, parameter lines)`` of every model/method/solver/experiment.

    Parameters
    ----------
    kind : {"models", "methods", "solvers", "experiments"}
        What to list; models include those registered by installed packages (entry points).

    Returns
    -------
    list of (str, str, list of str)

    Raises
    ------
    ConfigError
        An unknown ``kind``.
    """
    if kind == "models":
        rows = []
        for spec in MODELS.values():
            lines = [p.describe(k) for k, p in (spec.params or {}).items()]
            rows.append((spec.name, spec.description, lines))
        for name, ep in sorted(entry_points().items()):
            rows.append((name, f"registered by an installed package ({ep.value})", []))
        return rows
    if kind == "methods":
        return [(m.name, m.description, []) for m in METHODS.values()]
    if kind == "solvers":
        return [(s.name, s.description, []) for s in SOLVERS.values()]
    if kind == "experiments":
        return [(name, get_experiment(name).description, []) for name in EXPERIMENTS]
    raise ConfigError(f"nothing to list called {kind!r}")
