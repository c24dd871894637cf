"""The spaces ``V`` that states of isospectral flows live in.

Every space implements :class:`Algebra`. Constructors::

    so(n), u(n), su(n), sym(n), herm(n), sp(2m), sl2(), gl(n, complex=False)

and the compact vector forms of ``so(3)^N`` and ``sl(2,R)^N`` on ``(N, 3)`` arrays::

    so3_vectors(N), sl2_vectors(N)

and the semidirect products ``g x| g*`` (pairs of fields, :mod:`isoflow.algebras.semidirect`)::

    semidirect(so(n)), semidirect(u(n)), semidirect(su(n))   # (Theta, W), shape (2, n, n)
    se3_vectors()                                            # the heavy top, (Gamma, M), (2, 3)
"""

from ._base import Algebra as Algebra
from ._base import MatrixAlgebra as MatrixAlgebra
from .general import GeneralLinear as GeneralLinear
from .general import gl as gl
from .hermitian import Hermitian as Hermitian
from .hermitian import herm as herm
from .orthogonal import SpecialOrthogonal as SpecialOrthogonal
from .orthogonal import so as so
from .semidirect import SE3Vectors as SE3Vectors
from .semidirect import SemidirectProduct as SemidirectProduct
from .semidirect import se3_vectors as se3_vectors
from .semidirect import semidirect as semidirect
from .sl2_vectors import SL2Vectors as SL2Vectors
from .sl2_vectors import sl2_vectors as sl2_vectors
from .spin import SpinVectors as SpinVectors
from .spin import so3_vectors as so3_vectors
from .stacked import Stacked as Stacked
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
    "SE3Vectors",
    "SL2Vectors",
    "SemidirectProduct",
    "SpecialOrthogonal",
    "SpecialUnitary",
    "SpinVectors",
    "Stacked",
    "Symmetric",
    "Symplectic",
    "Unitary",
    "gl",
    "herm",
    "se3_vectors",
    "semidirect",
    "sl2",
    "sl2_vectors",
    "so",
    "so3_vectors",
    "sp",
    "su",
    "sym",
    "u",
]
