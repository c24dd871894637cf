r"""The unitary algebras :math:`\mathfrak{u}(n)` and :math:`\mathfrak{su}(n)` (skew-Hermitian)."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._eig import eigvalsh
from ._base import MatrixAlgebra

__all__ = ["SpecialUnitary", "Unitary", "su", "u"]


class Unitary(MatrixAlgebra):
    r""":math:`\mathfrak{u}(n) = \{W \in \mathbb{C}^{n\times n} : W^\dagger = -W\}`.

    Its own normalizer; real dimension :math:`n^2`. Casimirs: eigenvalues of the Hermitian
    matrix :math:`iW` in ascending order.
    """

    def __init__(self, n: int) -> None:
        super().__init__(n, np.complex128, f"u({n})")

    @property
    def normalizer(self) -> Unitary:
        return self

    transpose_sign = -1

    def sigma(self, Y: NDArray[Any]) -> NDArray[Any]:
        r"""Minus the conjugate transpose, :math:`-Y^\dagger`.

        Parameters
        ----------
        Y : ndarray, shape (*batch, n, n)
            Complex matrices.

        Returns
        -------
        ndarray, shape (*batch, n, n)
        """
        return -np.conj(np.swapaxes(Y, -1, -2))

    def casimirs(self, W: NDArray[Any]) -> NDArray[Any]:
        """The eigenvalues of the Hermitian matrix :math:`iW`, in ascending order.

        Parameters
        ----------
        W : ndarray, shape (*batch, n, n)
            Skew-Hermitian matrices (traceless for ``su(n)``).

        Returns
        -------
        ndarray, shape (*batch, n)
            Real.
        """
        return eigvalsh(1j * W)


class SpecialUnitary(Unitary):
    r""":math:`\mathfrak{su}(n)`: traceless skew-Hermitian matrices, real dimension :math:`n^2-1`.

    ``B`` may take values in the larger normalizer :math:`\mathfrak{u}(n)` (the trace part of
    ``B`` commutes with everything and does not act).
    """

    traceless = True

    def __init__(self, n: int) -> None:
        super().__init__(n)
        self.name = f"su({n})"

    @property
    def normalizer(self) -> Unitary:
        return Unitary(self.n)

    @property
    def stage_algebra(self) -> Unitary:
        return Unitary(self.n)


def u(n: int) -> Unitary:
    r"""The Lie algebra :math:`\mathfrak{u}(n)` of skew-Hermitian ``n x n`` matrices."""
    return Unitary(n)


def su(n: int) -> SpecialUnitary:
    r"""The Lie algebra :math:`\mathfrak{su}(n)` of traceless skew-Hermitian matrices."""
    return SpecialUnitary(n)
