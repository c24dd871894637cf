"""isoflow: structure-preserving integration of isospectral flows and Lie–Poisson systems.

The core is the isospectral minimal midpoint (IsoMP) of M. Viviani, *A minimal-variable
symplectic method for isospectral flows*. Quick start::

    import isoflow as iso
    alg = iso.algebras.so(10)
    prob = iso.IsospectralProblem(B=my_B, algebra=alg, hamiltonian=my_H)
    sol = iso.solve(prob, iso.IsoMP(), y0=W0, dt=0.1, t1=100.0, save_every=10)

Importing the package loads the numerical core only (spaces, problems, methods, solvers, the
time loop, diagnostics). The rest loads on first use (PEP 562): ``iso.models``, ``iso.sphere``,
``iso.threads``, ``iso.io`` (HDF5), ``iso.registry``, ``iso.experiments``, ``iso.plotting``
(matplotlib), ``iso.sweep`` (sweeps on dask.distributed: ``iso.sweep.run("sweep.toml",
"out")``) and ``iso.reference_solution`` (SciPy's integrators); numba loads when a run first
takes a compiled path.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from . import _numba_cache
from . import algebras as algebras
from . import noise as noise
from . import splitting as splitting
from ._errors import ArgumentTypeError as ArgumentTypeError
from ._errors import ConvergenceError as ConvergenceError
from ._errors import DtypeError as DtypeError
from ._errors import InvalidBError as InvalidBError
from ._errors import IsoflowError as IsoflowError
from ._errors import ModelChangedError as ModelChangedError
from ._errors import NonFiniteError as NonFiniteError
from ._errors import NotInSpaceError as NotInSpaceError
from ._errors import ParameterError as ParameterError
from ._errors import ResultFileError as ResultFileError
from ._errors import ResultWriteError as ResultWriteError
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
from .methods import StochasticHeun as StochasticHeun
from .methods import StochasticIsoMP as StochasticIsoMP
from .methods import Strang as Strang
from .nonlinear import FixedPoint as FixedPoint
from .nonlinear import Newton as Newton
from .problems import IsospectralProblem as IsospectralProblem
from .splitting import Forcing as Forcing
from .splitting import LinearPart as LinearPart
from .splitting import ModalLinearPart as ModalLinearPart
from .splitting import StochasticForcing as StochasticForcing

# numba loads later, on a run's first compiled path; a source checkout's cached loops that a
# change to an inlined block left stale go first (isoflow._numba_cache).
_numba_cache.refresh_checkout_cache()

if TYPE_CHECKING:  # what __getattr__ provides, for type checkers and editors
    from . import ensemble as ensemble
    from . import experiments as experiments
    from . import io as io
    from . import models as models
    from . import noise as noise
    from . import plotting as plotting
    from . import registry as registry
    from . import sphere as sphere
    from . import sweep as sweep
    from . import threads as threads
    from ._version import __version__ as __version__
    from .reference import reference_solution as reference_solution

#: Submodules loaded on first attribute access.
_LAZY_MODULES = frozenset(
    {"ensemble", "experiments", "io", "models", "noise", "plotting", "registry", "sphere", "sweep"}
    | {"threads"}
)
#: Attributes loaded on first access: name -> (module, attribute).
_LAZY_ATTRIBUTES = {
    "__version__": ("._version", "__version__"),
    "reference_solution": (".reference", "reference_solution"),
}


def __getattr__(name: str) -> Any:
    """Load the lazy submodules and attributes (PEP 562)."""
    if name in _LAZY_MODULES:
        return importlib.import_module(f".{name}", __name__)
    if name in _LAZY_ATTRIBUTES:
        module, attr = _LAZY_ATTRIBUTES[name]
        value = getattr(importlib.import_module(module, __name__), attr)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | _LAZY_MODULES | set(_LAZY_ATTRIBUTES))


__all__ = [
    "RK4",
    "ArgumentTypeError",
    "ClassicalMidpoint",
    "CompiledB",
    "Composition",
    "ConvergenceError",
    "Diagnostics",
    "DtypeError",
    "ElementwiseLinear",
    "FixedPoint",
    "Forcing",
    "InvalidBError",
    "IsoMP",
    "IsoSyRK",
    "IsoflowError",
    "IsospectralProblem",
    "Kernel",
    "LinearPart",
    "Method",
    "ModalLinearPart",
    "ModelChangedError",
    "Newton",
    "NonFiniteError",
    "NotInSpaceError",
    "PairwiseVortex",
    "ParameterError",
    "ResultFileError",
    "ResultWriteError",
    "ShapeError",
    "Solution",
    "SolveStats",
    "SphericalMidpoint",
    "SpinNeighbourSum",
    "StepResult",
    "StepSizeError",
    "StochasticForcing",
    "StochasticHeun",
    "StochasticIsoMP",
    "Strang",
    "TimeSpanError",
    "UnsupportedAlgebraError",
    "__version__",
    "algebras",
    "ensemble",
    "experiments",
    "io",
    "models",
    "noise",
    "plotting",
    "reference_solution",
    "registry",
    "solve",
    "sphere",
    "splitting",
    "step",
    "sweep",
    "threads",
]
