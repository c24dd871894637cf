"""The spaces ``V`` that states of isospectral flows live in.

Every space implements :class:`Algebra`. Constructors::

    so(n), u(n), su(n), sym(n), herm(n), sp(2m), sl2(), gl(n, complex=False)
"""

from ._base import Algebra as Algebra
from ._base import MatrixAlgebra as MatrixAlgebra
from .general import GeneralLinear as GeneralLinear
from .general import gl as gl
from .hermitian import Hermitian as Hermitian
from .hermitian import herm as herm
from .orthogonal import SpecialOrthogonal as SpecialOrthogonal
from .orthogonal import so as so
from .symmetric import Symmetric as Symmetric
from .symmetric import sym as sym
from .symplectic import Symplectic as Symplectic
from .symplectic import sl2 as sl2
from .symplectic import sp as sp
from .unitary import SpecialUnitary as SpecialUnitary
from .unitary import Unitary as Unitary
from .unitary import su as su
from .unitary import u as u

__all__ = [
    "Algebra",
    "GeneralLinear",
    "Hermitian",
    "MatrixAlgebra",
    "SpecialOrthogonal",
    "SpecialUnitary",
    "Symmetric",
    "Symplectic",
    "Unitary",
    "gl",
    "herm",
    "sl2",
    "so",
    "sp",
    "su",
    "sym",
    "u",
]
