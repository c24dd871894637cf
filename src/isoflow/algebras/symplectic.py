r"""Real symplectic algebras :math:`\mathfrak{sp}(2m)` and :math:`\mathfrak{sl}(2,\mathbb{R})`."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._errors import ParameterError
from ._base import MatrixAlgebra

__all__ = ["Symplectic", "sl2", "sp"]


class Symplectic(MatrixAlgebra):
    r""":math:`\mathfrak{sp}(2m) = \{W \in \mathbb{R}^{2m\times 2m} : W^T J + J W = 0\}`.

    With :math:`J = \begin{pmatrix} 0 & I_m \\ -I_m & 0\end{pmatrix}` (attribute :attr:`J`),
    the elements are :math:`\begin{pmatrix} A & S \\ T & -A^T\end{pmatrix}` with ``S, T``
    symmetric. ``V`` is the fixed set of the exact involution :math:`\sigma(Y) = J Y^T J`.
    The algebra is its own normalizer, is closed under transposition (:math:`J^2 = -I` is
    central), real dimension :math:`2m^2 + m`. Casimirs: ``Tr(W^k)``, ``k = 1..2m`` (odd ones
    vanish); the matrices are not normal, so traces of powers are used instead of eigenvalues.
    ``sp(2) = sl(2, R)``.

    Parameters
    ----------
    size : int
        Matrix size ``2m`` (even, at least 2).
    name : str, optional
        Name of the space (default ``"sp(size)"``; :func:`sl2` gives ``"sl(2,R)"``).

    Raises
    ------
    ParameterError
        ``size`` is not an even integer ``>= 2``.
    """

    casimirs_are_eigenvalues = False

    def __init__(self, size: int, name: str | None = None) -> None:
        if not isinstance(size, (int, np.integer)) or size < 2 or size % 2:
            raise ParameterError(f"sp(2m) needs an even matrix size >= 2, got {size!r}")
        super().__init__(size, np.float64, name or f"sp({size})")
        self.m = size // 2
        m = self.m
        J = np.zeros((size, size))
        J[:m, m:] = np.eye(m)
        J[m:, :m] = -np.eye(m)
        self.J = J

    @property
    def normalizer(self) -> Symplectic:
        return self

    def sigma(self, Y: NDArray[Any]) -> NDArray[Any]:
        """The involution :math:`J Y^T J`.

        Parameters
        ----------
        Y : ndarray, shape (*batch, n, n)
            Real matrices, ``n = 2m``.

        Returns
        -------
        ndarray, shape (*batch, n, n)
        """
        # J Y^T J = [[-Y22^T, Y12^T], [Y21^T, -Y11^T]] for Y = [[Y11, Y12], [Y21, Y22]]
        m = self.m
        Yt = np.swapaxes(Y, -1, -2)
        out = np.empty_like(Y)
        out[..., :m, :m] = -Yt[..., m:, m:]
        out[..., :m, m:] = Yt[..., m:, :m]
        out[..., m:, :m] = Yt[..., :m, m:]
        out[..., m:, m:] = -Yt[..., :m, :m]
        return out

    def casimirs(self, W: NDArray[Any]) -> NDArray[Any]:
        """``Tr(W^k)``, ``k = 1..2m`` (the odd ones vanish), real.

        Parameters
        ----------
        W : ndarray, shape (*batch, n, n)
            Elements of ``sp(2m)``, ``n = 2m``.

        Returns
        -------
        ndarray, shape (*batch, 2m)
            Real.
        """
        return np.real(self.trace_powers(W))


def sp(size: int) -> Symplectic:
    r"""The real symplectic algebra :math:`\mathfrak{sp}(2m)` of ``size = 2m`` square matrices."""
    return Symplectic(size)


def sl2() -> Symplectic:
    r""":math:`\mathfrak{sl}(2,\mathbb{R})` as ``2 x 2`` traceless real matrices (``= sp(2)``)."""
    return Symplectic(2, name="sl(2,R)")
