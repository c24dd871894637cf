r"""The special orthogonal algebra :math:`\mathfrak{so}(n)` of real skew-symmetric matrices."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._eig import skew_eigvalsh
from ._base import MatrixAlgebra

__all__ = ["SpecialOrthogonal", "so"]


class SpecialOrthogonal(MatrixAlgebra):
    r""":math:`\mathfrak{so}(n) = \{W \in \mathbb{R}^{n\times n} : W^T = -W\}`.

    Its own normalizer (for :math:`n \ge 3`, up to the centre of ``gl(n)``, which does not act),
    real dimension :math:`n(n-1)/2`. Casimirs: the eigenvalues of the Hermitian matrix
    :math:`iW`, in ascending order (the spectrum of ``W`` is :math:`\{-i\lambda\}`).
    """

    def __init__(self, n: int) -> None:
        super().__init__(n, np.float64, f"so({n})")

    @property
    def normalizer(self) -> SpecialOrthogonal:
        return self

    transpose_sign = -1

    def sigma(self, Y: NDArray[Any]) -> NDArray[Any]:
        """Minus the transpose, :math:`-Y^T`.

        Parameters
        ----------
        Y : ndarray, shape (*batch, n, n)
            Real matrices.

        Returns
        -------
        ndarray, shape (*batch, n, n)
        """
        return -np.swapaxes(Y, -1, -2)

    def casimirs(self, W: NDArray[Any]) -> NDArray[Any]:
        r"""The eigenvalues of the Hermitian matrix :math:`iW`, in ascending order.

        Parameters
        ----------
        W : ndarray, shape (*batch, n, n)
            Real skew-symmetric matrices.

        Returns
        -------
        ndarray, shape (*batch, n)
            Real, in pairs :math:`\pm\lambda` (and a zero for odd ``n``).
        """
        return skew_eigvalsh(W)


def so(n: int) -> SpecialOrthogonal:
    r"""The Lie algebra :math:`\mathfrak{so}(n)` of real skew-symmetric ``n x n`` matrices."""
    return SpecialOrthogonal(n)
