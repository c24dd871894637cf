"""Shared machinery of the compact vector forms: ``N`` particles in ``R^3``, shape ``(N, 3)``."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

if TYPE_CHECKING:
    import scipy.sparse as sp

from .._errors import ParameterError
from ._base import Algebra

__all__ = ["ParticleVectors"]

Array = NDArray[Any]


class ParticleVectors(Algebra):
    """``N`` copies of a 3-dimensional Lie algebra written as vectors, states ``(*batch, N, 3)``.

    Every real ``(N, 3)`` array is an element, the space is its own normalizer, the pairing is
    the Euclidean dot product over all particles and the basis is the standard one. Subclasses
    give the products (``bracket``, ``bracket_and_triple``), ``dagger`` and the Casimirs.
    """

    #: Format of :attr:`name`, filled with ``N``.
    name_template: str = "R^3^{N}"

    def __init__(self, N: int) -> None:
        if not isinstance(N, (int, np.integer)) or isinstance(N, bool) or N < 1:
            raise ParameterError(f"the number of particles N must be a positive integer, got {N!r}")
        self.N = int(N)
        self.shape = (self.N, 3)
        self.dtype = np.dtype(np.float64)
        self.name = self.name_template.format(N=self.N)

    @property
    def normalizer(self) -> ParticleVectors:
        return self

    def project(self, W: Array) -> Array:
        """Every real ``(N, 3)`` array lies in the space: return it as ``float64``
        (no copy when it already is; methods never write into their inputs).

        Complex input is mapped to its real part (the orthogonal projection of the
        complexification onto the real space).

        Parameters
        ----------
        W : ndarray, shape (*batch, N, 3)
            Vectors, one per particle.

        Returns
        -------
        ndarray, shape (*batch, N, 3)
        """
        W = np.asarray(W)
        if np.iscomplexobj(W):
            W = W.real
        return W.astype(np.float64, copy=False)

    def casimir_scale(self, W0: Array) -> Array:
        r"""Scale of the per-particle quadratic Casimirs: the Euclidean :math:`|w_i|^2`
        (a particle at the origin uses the largest one), the size of their rounding errors.

        Parameters
        ----------
        W0 : ndarray, shape (*batch, N, 3)
            The initial states.

        Returns
        -------
        ndarray, shape (*batch, N)
        """
        sq = np.einsum("...i,...i->...", W0, W0)
        fallback = np.max(sq, axis=-1, keepdims=True) if sq.ndim else sq
        fallback = np.where(fallback > 0, fallback, 1.0)
        return np.where(sq > 0, sq, fallback)

    def _basis_matrix(self) -> sp.csr_array:
        import scipy.sparse as sp

        return sp.identity(3 * self.N, format="csr", dtype=np.float64)
