"""The physical systems, each a function returning ``(problem, initial_state)``.

The model modules are imported on first use (``iso.models.rigid_body`` imports only
``rigid_body.py``), so that a model whose kernel is compiled code loads numba only when used.
"""

from __future__ import annotations

import importlib
from typing import Any

from .._errors import ParameterError as ParameterError

#: public name -> module that defines it
_WHERE = {
    "brockett": "brockett",
    "coriolis_matrix": "euler_sphere",
    "euler_sphere": "euler_sphere",
    "heisenberg_chain": "heisenberg_chain",
    "hyperbolic_vortices": "hyperbolic_vortices",
    "jacobi_coefficients": "toda",
    "jacobi_matrix": "toda",
    "off_band": "toda",
    "rigid_body": "rigid_body",
    "sphere_vortices": "sphere_vortices",
    "spin_lattice": "spin_lattice",
    "toda": "toda",
}

__all__ = ["ParameterError", *sorted(_WHERE)]


def __getattr__(name: str) -> Any:
    if name in _WHERE:
        value = getattr(importlib.import_module(f".{_WHERE[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)
