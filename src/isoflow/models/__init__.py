"""The physical systems, each a function returning ``(problem, initial_state)``.

Every public name of the models is an attribute of this package (``iso.models.rigid_body``,
``from isoflow.models import BROCKETT_DEFAULT_SCALE``). Each model lives in a private module
named after it (``_rigid_body.py``), imported on first use: ``iso.models.rigid_body`` imports
only ``_rigid_body.py``, so that a model whose kernel is compiled code loads numba only when
used. The modules' names differ from the functions', so importing a module never rebinds a
function's name.
"""

from __future__ import annotations

import importlib
from typing import Any

from .._errors import ParameterError as ParameterError

#: public name -> module that defines it
_WHERE = {
    "BROCKETT_DEFAULT_SCALE": "_brockett",
    "PAPER_CONFIGS": "_hyperbolic_vortices",
    "brockett": "_brockett",
    "coriolis_matrix": "_euler_sphere",
    "euler_sphere": "_euler_sphere",
    "heavy_top": "_heavy_top",
    "heisenberg_chain": "_heisenberg_chain",
    "hyperbolic_vortices": "_hyperbolic_vortices",
    "jacobi_coefficients": "_toda",
    "jacobi_matrix": "_toda",
    "mhd_sphere": "_mhd_sphere",
    "off_band": "_toda",
    "paper_inertia_d": "_rigid_body",
    "paper_spin_curve": "_heisenberg_chain",
    "paper_vortex_config": "_hyperbolic_vortices",
    "qg_operator": "_qg_sphere",
    "qg_sphere": "_qg_sphere",
    "rigid_body": "_rigid_body",
    "sphere_vortices": "_sphere_vortices",
    "spin_lattice": "_spin_lattice",
    "spin_lattice_field": "_spin_lattice",
    "toda": "_toda",
}

__all__ = ["ParameterError", *sorted(_WHERE)]


def __getattr__(name: str) -> Any:
    if name in _WHERE:
        from ..threads import check_numba_environment

        check_numba_environment()  # the models' modules import numba
        value = getattr(importlib.import_module(f".{_WHERE[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)
