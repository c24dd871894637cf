r"""The general linear algebra :math:`\mathfrak{gl}(n)`, real or complex."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from ._base import MatrixAlgebra

__all__ = ["GeneralLinear", "gl"]


class GeneralLinear(MatrixAlgebra):
    r""":math:`\mathfrak{gl}(n, \mathbb{R})` or :math:`\mathfrak{gl}(n, \mathbb{C})`.

    Its own normalizer; no symmetry to exploit, so the commutator costs two products.
    Real dimension :math:`n^2` (real) or :math:`2n^2` (complex). Casimirs: ``Tr(W^k)``,
    ``k = 1..n`` (real parts for the real algebra).
    """

    structured = False
    casimirs_are_eigenvalues = False

    def __init__(self, n: int, complex: bool = False) -> None:
        dtype = np.complex128 if complex else np.float64
        super().__init__(n, dtype, f"gl({n},{'C' if complex else 'R'})")

    @property
    def normalizer(self) -> GeneralLinear:
        return self

    def sigma(self, Y: NDArray[Any]) -> NDArray[Any]:
        """The identity: every matrix lies in ``gl(n)``.

        Parameters
        ----------
        Y : ndarray, shape (*batch, n, n)
            Matrices.

        Returns
        -------
        ndarray, shape (*batch, n, n)
        """
        return Y

    def project(self, W: NDArray[Any]) -> NDArray[Any]:
        """``W`` itself, converted to the algebra's dtype (no copy when it has it).

        Parameters
        ----------
        W : ndarray, shape (*batch, n, n)
            Matrices.

        Returns
        -------
        ndarray, shape (*batch, n, n)
        """
        return np.asarray(W, dtype=self.dtype) if W.dtype != self.dtype else W

    def casimirs(self, W: NDArray[Any]) -> NDArray[Any]:
        """``Tr(W^k)``, ``k = 1..n`` (real parts for the real algebra).

        Parameters
        ----------
        W : ndarray, shape (*batch, n, n)
            Elements of ``gl(n)``.

        Returns
        -------
        ndarray, shape (*batch, n)
            Complex for the complex algebra, real otherwise.
        """
        tp = self.trace_powers(W)
        return tp if self.is_complex else np.real(tp)


def gl(n: int, complex: bool = False) -> GeneralLinear:
    r"""All ``n x n`` matrices, real (default) or complex.

    Parameters
    ----------
    n : int
        Matrix size (a positive integer).
    complex : bool
        Complex matrices (``complex128``) instead of real ones (``float64``, the default).
    """
    return GeneralLinear(n, complex=complex)
