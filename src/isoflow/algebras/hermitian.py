r"""Hermitian matrices :math:`\mathrm{Herm}(n)`; normalizer :math:`\mathfrak{u}(n)`."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._eig import eigvalsh
from ._base import MatrixAlgebra
from .unitary import Unitary

__all__ = ["Hermitian", "herm"]


class Hermitian(MatrixAlgebra):
    r""":math:`\mathrm{Herm}(n) = \{W \in \mathbb{C}^{n\times n} : W^\dagger = W\}`.

    ``B`` maps into :math:`\mathfrak{u}(n)`; real dimension :math:`n^2`. Casimirs: the (real)
    eigenvalues in ascending order.
    """

    def __init__(self, n: int) -> None:
        super().__init__(n, np.complex128, f"herm({n})")

    @property
    def normalizer(self) -> Unitary:
        return Unitary(self.n)

    transpose_sign = 1

    def sigma(self, Y: NDArray[Any]) -> NDArray[Any]:
        r"""The conjugate transpose :math:`Y^\dagger`.

        Parameters
        ----------
        Y : ndarray, shape (*batch, n, n)
            Complex matrices.

        Returns
        -------
        ndarray, shape (*batch, n, n)
        """
        return np.conj(np.swapaxes(Y, -1, -2))

    def casimirs(self, W: NDArray[Any]) -> NDArray[Any]:
        """The eigenvalues of ``W`` in ascending order.

        Parameters
        ----------
        W : ndarray, shape (*batch, n, n)
            Hermitian matrices.

        Returns
        -------
        ndarray, shape (*batch, n)
            Real.
        """
        return eigvalsh(W)


def herm(n: int) -> Hermitian:
    r"""Hermitian ``n x n`` matrices; ``B`` maps into :math:`\mathfrak{u}(n)`."""
    return Hermitian(n)
