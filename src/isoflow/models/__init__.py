"""The physical systems, each a function returning ``(problem, initial_state)``.

The model modules are imported on first use (``iso.models.rigid_body`` imports only
``rigid_body.py``), so that a model whose kernel is compiled code loads numba only when used.
"""

from __future__ import annotations

import importlib
import sys
import types
from typing import Any

from .._errors import ParameterError as ParameterError

#: public name -> module that defines it
_WHERE = {
    "brockett": "brockett",
    "coriolis_matrix": "euler_sphere",
    "euler_sphere": "euler_sphere",
    "heavy_top": "heavy_top",
    "heisenberg_chain": "heisenberg_chain",
    "hyperbolic_vortices": "hyperbolic_vortices",
    "jacobi_coefficients": "toda",
    "jacobi_matrix": "toda",
    "mhd_sphere": "mhd_sphere",
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


class _Models(types.ModuleType):
    """This package, keeping each model function bound under its name.

    Importing a submodule (``from isoflow.models.brockett import BROCKETT_DEFAULT_SCALE``, or
    ``sphere_vortices.py`` importing helpers of ``hyperbolic_vortices.py``) makes the import
    system set the package attribute of the submodule's name to the module, which would shadow
    the function of the same name (``iso.models.brockett(...)``: "'module' object is not
    callable"). The function is bound instead.
    """

    def __setattr__(self, name: str, value: Any) -> None:
        if isinstance(value, types.ModuleType) and _WHERE.get(name) == name:
            value = getattr(value, name)
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Models
