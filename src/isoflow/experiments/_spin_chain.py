"""What the three spin-chain experiments (Sec. 3.3) share: the two methods they compare."""

from __future__ import annotations

from .. import registry
from ..methods import Method
from ..nonlinear import NonlinearSolver

__all__ = ["LABELS", "METHODS", "method"]

#: Key in the experiments' data and JSON summaries -> the method's name in the registry.
METHODS = {"isomp": "isomp", "spherical": "spherical-midpoint"}
#: Key -> legend label.
LABELS = {"isomp": "isospectral minimal midpoint (IsoMP)", "spherical": "spherical midpoint"}


def method(key: str, solver: NonlinearSolver | None = None) -> Method:
    """The method of ``key`` (``"isomp"`` or ``"spherical"``) with ``solver``."""
    return registry.make_method(METHODS[key], solver)
