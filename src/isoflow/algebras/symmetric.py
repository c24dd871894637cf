r"""Real symmetric matrices :math:`\mathrm{Sym}(n)`; normalizer :math:`\mathfrak{so}(n)`."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._eig import eigvalsh
from ._base import MatrixAlgebra
from .orthogonal import SpecialOrthogonal

__all__ = ["Symmetric", "sym"]


class Symmetric(MatrixAlgebra):
    r""":math:`\mathrm{Sym}(n) = \{W \in \mathbb{R}^{n\times n} : W^T = W\}`.

    Not a Lie algebra; ``B`` must take values in its normalizer :math:`\mathfrak{so}(n)`.
    Real dimension :math:`n(n+1)/2`. Casimirs: the eigenvalues in ascending order.
    """

    def __init__(self, n: int) -> None:
        super().__init__(n, np.float64, f"sym({n})")

    @property
    def normalizer(self) -> SpecialOrthogonal:
        return SpecialOrthogonal(self.n)

    transpose_sign = 1

    def sigma(self, Y: NDArray[Any]) -> NDArray[Any]:
        """The transpose, :math:`Y^T`.

        Parameters
        ----------
        Y : ndarray, shape (*batch, n, n)
            Real matrices.

        Returns
        -------
        ndarray, shape (*batch, n, n)
        """
        return np.swapaxes(Y, -1, -2)

    def casimirs(self, W: NDArray[Any]) -> NDArray[Any]:
        """The eigenvalues of ``W`` in ascending order.

        Parameters
        ----------
        W : ndarray, shape (*batch, n, n)
            Real symmetric matrices.

        Returns
        -------
        ndarray, shape (*batch, n)
            Real.
        """
        return eigvalsh(W)


def sym(n: int) -> Symmetric:
    r"""Real symmetric ``n x n`` matrices; ``B`` maps into :math:`\mathfrak{so}(n)`."""
    return Symmetric(n)
