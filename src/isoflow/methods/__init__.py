"""Time-stepping methods, one per module; each is a small frozen dataclass."""

from ._base import Method as Method
from ._base import StepResult as StepResult
from .classical_midpoint import ClassicalMidpoint as ClassicalMidpoint
from .composition import Composition as Composition
from .explicit_rk import RK4 as RK4
from .isomp import IsoMP as IsoMP
from .isosyrk import IsoSyRK as IsoSyRK
from .spherical_midpoint import SphericalMidpoint as SphericalMidpoint
from .stochastic_heun import StochasticHeun as StochasticHeun
from .stochastic_isomp import StochasticIsoMP as StochasticIsoMP
from .strang import Strang as Strang

__all__ = [
    "RK4",
    "ClassicalMidpoint",
    "Composition",
    "IsoMP",
    "IsoSyRK",
    "Method",
    "SphericalMidpoint",
    "StepResult",
    "StochasticHeun",
    "StochasticIsoMP",
    "Strang",
]
