"""isoflow: structure-preserving integration of isospectral flows and Lie–Poisson systems.

The core is the isospectral minimal midpoint (IsoMP) of M. Viviani, *A minimal-variable
symplectic method for isospectral flows*. Quick start::

    import isoflow as iso
    alg = iso.algebras.so(10)
    prob = iso.IsospectralProblem(B=my_B, algebra=alg, hamiltonian=my_H)
    sol = iso.solve(prob, iso.IsoMP(), y0=W0, dt=0.1, t1=100.0, save_every=10)
"""

from importlib.metadata import PackageNotFoundError, version

from . import algebras as algebras
from . import models as models
from . import sphere as sphere
from . import threads as threads
from ._errors import ConvergenceError as ConvergenceError
from ._errors import DtypeError as DtypeError
from ._errors import InvalidBError as InvalidBError
from ._errors import IsoflowError as IsoflowError
from ._errors import NonFiniteError as NonFiniteError
from ._errors import NotInSpaceError as NotInSpaceError
from ._errors import ParameterError as ParameterError
from ._errors import ShapeError as ShapeError
from ._errors import StepSizeError as StepSizeError
from ._errors import TimeSpanError as TimeSpanError
from ._errors import UnsupportedAlgebraError as UnsupportedAlgebraError
from ._solve import Solution as Solution
from ._solve import SolveStats as SolveStats
from ._solve import solve as solve
from ._solve import step as step
from .diagnostics import Diagnostics as Diagnostics
from .kernels import CompiledB as CompiledB
from .kernels import ElementwiseLinear as ElementwiseLinear
from .kernels import Kernel as Kernel
from .kernels import PairwiseVortex as PairwiseVortex
from .kernels import SpinNeighbourSum as SpinNeighbourSum
from .methods import RK4 as RK4
from .methods import ClassicalMidpoint as ClassicalMidpoint
from .methods import Composition as Composition
from .methods import IsoMP as IsoMP
from .methods import IsoSyRK as IsoSyRK
from .methods import Method as Method
from .methods import SphericalMidpoint as SphericalMidpoint
from .methods import StepResult as StepResult
from .nonlinear import FixedPoint as FixedPoint
from .nonlinear import Newton as Newton
from .problems import IsospectralProblem as IsospectralProblem
from .reference import reference_solution as reference_solution

try:
    __version__ = version("isoflow")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0+unknown"

from . import experiments as experiments
from . import io as io
from . import registry as registry

__all__ = [
    "RK4",
    "ClassicalMidpoint",
    "CompiledB",
    "Composition",
    "ConvergenceError",
    "Diagnostics",
    "DtypeError",
    "ElementwiseLinear",
    "FixedPoint",
    "InvalidBError",
    "IsoMP",
    "IsoSyRK",
    "IsoflowError",
    "IsospectralProblem",
    "Kernel",
    "Method",
    "Newton",
    "NonFiniteError",
    "NotInSpaceError",
    "PairwiseVortex",
    "ParameterError",
    "ShapeError",
    "Solution",
    "SolveStats",
    "SphericalMidpoint",
    "SpinNeighbourSum",
    "StepResult",
    "StepSizeError",
    "TimeSpanError",
    "UnsupportedAlgebraError",
    "__version__",
    "algebras",
    "experiments",
    "io",
    "models",
    "reference_solution",
    "registry",
    "solve",
    "sphere",
    "step",
    "threads",
]
