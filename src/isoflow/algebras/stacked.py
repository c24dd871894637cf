r"""``s`` copies of a space stacked on one extra axis: the unknowns of a multi-stage method.

An element of :math:`V^s` is an array of shape ``(*batch, s, *V.shape)``: the stage axis sits
right before the element axes of ``V``, after the ensemble axes, so the batch of
:math:`V^s` is that of ``V`` and a nonlinear solver converges per ensemble member over all
stages at once. Every operation acts on each copy (the operations of ``V`` broadcast over the
stage axis); the norm and the pairing sum over the copies, and coordinates are those of the
copies one after the other.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:
    import scipy.sparse as sp

from .._errors import ParameterError
from ._base import Algebra

__all__ = ["Stacked"]

Array = NDArray[Any]


class Stacked(Algebra):
    """The direct sum of ``copies`` copies of ``base``, shape ``(copies, *base.shape)``.

    Parameters
    ----------
    base : Algebra
        The space ``V`` of each copy.
    copies : int
        Number of copies ``s >= 1``.
    """

    def __init__(self, base: Algebra, copies: int) -> None:
        if not isinstance(copies, (int, np.integer)) or isinstance(copies, bool) or copies < 1:
            raise ParameterError(f"copies must be a positive integer, got {copies!r}")
        self.base = base
        self.copies = int(copies)
        self.shape = (self.copies, *base.shape)
        self.dtype = base.dtype
        self.name = f"{base.name}^{self.copies}"

    @property
    def normalizer(self) -> Stacked:
        return Stacked(self.base.normalizer, self.copies)

    @property
    def stage_algebra(self) -> Stacked:
        return Stacked(self.base.stage_algebra, self.copies)

    @property
    def dim(self) -> int:
        return self.copies * self.base.dim

    def project(self, W: Array) -> Array:
        """The base's projection on every copy.

        Parameters
        ----------
        W : ndarray, shape (*batch, copies, *base.shape)
            Elements of the ambient space of the copies.

        Returns
        -------
        ndarray, shape (*batch, copies, *base.shape)
        """
        return self.base.project(W)

    def bracket(self, A: Array, X: Array) -> Array:
        return self.base.bracket(A, X)

    def bracket_and_triple(self, B: Array, X: Array) -> tuple[Array, Array]:
        return self.base.bracket_and_triple(B, X)

    @property
    def closed_form_stage(self) -> bool:  # type: ignore[override]
        return self.base.closed_form_stage

    def solve_stage(self, W: Array, B: Array, h: float) -> tuple[Array, Array]:
        return self.base.solve_stage(W, B, h)

    def solve_stage_jvp(self, W: Array, B: Array, dB: Array, h: float) -> Array:
        return self.base.solve_stage_jvp(W, B, dB, h)

    def casimirs(self, W: Array) -> Array:
        """The Casimirs of the copies, one after the other, shape ``(*batch, copies * m)``.

        Parameters
        ----------
        W : ndarray, shape (*batch, copies, *base.shape)
            Elements.

        Returns
        -------
        ndarray, shape (*batch, copies * m)
        """
        C = self.base.casimirs(W)
        return C.reshape(*C.shape[:-2], -1)

    def to_matrix(self, W: Array) -> Array:
        """The base's matrix representation of every copy.

        Parameters
        ----------
        W : ndarray, shape (*batch, copies, *base.shape)
            Elements (or values of ``B``).
        """
        return self.base.to_matrix(W)

    def from_matrix(self, M: Array) -> Array:
        """The base's inverse of :meth:`to_matrix` on every copy (not projected).

        Parameters
        ----------
        M : ndarray, shape (*batch, copies, ...)
            Matrices of the shape :meth:`to_matrix` returns.
        """
        return self.base.from_matrix(M)

    def to_coords(self, W: Array) -> Array:
        c = self.base.to_coords(np.asarray(W))
        return c.reshape(*c.shape[:-2], self.dim)

    def from_coords(self, coords: ArrayLike) -> Array:
        """The element with the given coordinates: those of the copies, one after the other.

        Parameters
        ----------
        coords : ndarray, shape (*batch, dim)
            Coordinates, ``dim = copies * base.dim``.

        Returns
        -------
        ndarray, shape (*batch, copies, *base.shape)
        """
        c = self._coords_array(coords)
        return self.base.from_coords(c.reshape(*c.shape[:-1], self.copies, self.base.dim))

    def _basis_matrix(self) -> sp.csr_array:
        """Block-diagonal basis in the flat representation of ``(copies, *base.shape)``
        (for complex spaces: all real parts, then all imaginary parts)."""
        basis = self.base.basis_matrix
        import scipy.sparse as sp

        eye = sp.identity(self.copies, format="csr")
        if not self.is_complex:
            return sp.csr_array(sp.kron(eye, basis))
        half = basis.shape[1] // 2
        re = sp.kron(eye, basis[:, :half])
        im = sp.kron(eye, basis[:, half:])
        return sp.csr_array(sp.hstack([re, im]))

    def __repr__(self) -> str:
        return f"<algebra {self.name} (stacked copies of {self.base.name})>"
