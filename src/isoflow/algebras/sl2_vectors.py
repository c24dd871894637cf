r"""The compact form :math:`(\mathbb{R}^3, \times_L)^N` of :math:`\mathfrak{sl}(2,\mathbb{R})^N`.

With :math:`L = \operatorname{diag}(1, 1, -1)`, the Lorentzian products are
:math:`a \cdot_L b = a \cdot (L b)` and :math:`a \times_L b = 2 L (a \times b)`. The paper's map

.. math::

    \varphi(x, y, z) = \begin{pmatrix} x & y + z \\ y - z & -x \end{pmatrix}

is a linear isomorphism :math:`\mathbb{R}^3 \to \mathfrak{sl}(2,\mathbb{R})` with

* :math:`[\varphi(a), \varphi(b)] = -\varphi(a \times_L b)` (an *anti*-isomorphism of
  :math:`(\mathbb{R}^3, \times_L)`, not an isomorphism as printed), so the matrix bracket reads
  ``bracket(A, X) = -(A x_L X)`` in vectors;
* :math:`\varphi(b)\varphi(x)\varphi(b) = \varphi\bigl(2 (b\cdot_L x)\, b - (b \cdot_L b)\, x\bigr)`
  (the printed ``M(a, b, c)`` returns raw matrix entries instead of coordinates; this is the
  corrected :math:`M(b, x, b)`);
* :math:`\operatorname{Tr}(\varphi(a)\varphi(b)) = 2\, a \cdot_L b`,
  :math:`\det \varphi(a) = -a \cdot_L a`, :math:`\varphi(a)^T = \varphi(L a)` and
  :math:`\operatorname{Tr}(\varphi(a)^T \varphi(b)) = 2\, a \cdot b`.

:class:`~isoflow.IsoMP` on :class:`SL2Vectors` is therefore the matrix method on
:math:`\mathfrak{sl}(2,\mathbb{R})` for every particle at once (the *hyperbolic midpoint*): one
step solves :math:`x = w_k + \tfrac h2 [b, x] + \tfrac{h^2}{4}\bigl(2 (b\cdot_L x)\, b -
(b\cdot_L b)\, x\bigr)`, :math:`[b, x] = -b \times_L x`, :math:`b = B(x)`, and sets
:math:`w_{k+1} = w_k - h\, b \times_L x`. The coadjoint orbits are the hyperboloids
:math:`w \cdot_L w = x^2 + y^2 - z^2 = \text{const}`, preserved exactly (up to rounding).

Pairing convention
------------------
Vectors are paired by the Euclidean dot product (:meth:`Algebra.inner`), *half* the Frobenius
pairing of the matrices, :math:`\operatorname{Tr}(\varphi(a)^T\varphi(b)) = 2\,a\cdot b`. The
dagger is :math:`\varphi(g)^T = \varphi(L g)`, i.e. ``dagger(g) = L g``. So
:meth:`IsospectralProblem.from_hamiltonian <isoflow.IsospectralProblem.from_hamiltonian>` with
the *Euclidean* gradient gives :math:`B = L \nabla H` and

.. math::

    \dot w_i = -(L\nabla_i H) \times_L w_i = w_i \times_L L \nabla_i H
             = 2 L (w_i \times L \nabla_i H),

with Poisson tensor :math:`P(w) = \operatorname{diag}(2 L \hat w_i L)` (twice the speed of the
same ``H`` on :math:`2\times 2` matrices with the Frobenius pairing).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._vectors import ParticleVectors
from .spin import cross

__all__ = ["L_DIAG", "SL2Vectors", "cross_L", "dot_L", "phi", "phi_inv", "sl2_vectors"]

Array = NDArray[Any]

#: Diagonal of :math:`L = \operatorname{diag}(1, 1, -1)`.
L_DIAG = np.array([1.0, 1.0, -1.0])


def dot_L(a: Array, b: Array) -> Array:
    r"""Lorentzian product :math:`a \cdot_L b = a_1 b_1 + a_2 b_2 - a_3 b_3` over the last axis."""
    return np.einsum("...i,...i->...", a * L_DIAG, b)


def cross_L(a: Array, b: Array) -> Array:
    r""":math:`a \times_L b = 2 L (a \times b)` over the last axis."""
    return (2.0 * L_DIAG) * cross(a, b)


def phi(w: ArrayLike) -> Array:
    r"""The paper's map :math:`(x, y, z) \mapsto \begin{pmatrix} x & y+z \\ y-z & -x
    \end{pmatrix}`, shape ``(..., 3) -> (..., 2, 2)``.

    Note :math:`[\varphi(a), \varphi(b)] = -\varphi(a \times_L b)`.
    """
    w = np.asarray(w, dtype=np.float64)
    x, y, z = w[..., 0], w[..., 1], w[..., 2]
    return np.stack(
        [np.stack([x, y + z], axis=-1), np.stack([y - z, -x], axis=-1)],
        axis=-2,
    )


def phi_inv(Q: ArrayLike) -> Array:
    r"""Coordinates of a ``2 x 2`` matrix: :math:`((Q_{11} - Q_{22})/2, (Q_{12} + Q_{21})/2,
    (Q_{12} - Q_{21})/2)`, shape ``(..., 2, 2) -> (..., 3)``.

    The inverse of :func:`phi` on :math:`\mathfrak{sl}(2,\mathbb{R})`; for a matrix with a trace
    it returns the coordinates of its traceless part.
    """
    Q = np.asarray(Q, dtype=np.float64)
    q11, q12, q21, q22 = Q[..., 0, 0], Q[..., 0, 1], Q[..., 1, 0], Q[..., 1, 1]
    return 0.5 * np.stack([q11 - q22, q12 + q21, q12 - q21], axis=-1)


class SL2Vectors(ParticleVectors):
    r""":math:`(\mathbb{R}^3, \times_L)^N \cong \mathfrak{sl}(2,\mathbb{R})^N`, shape ``(N, 3)``.

    Every real ``(N, 3)`` array is an element; the algebra is its own normalizer. Row ``i`` is
    particle ``i`` (coordinates ``(x, y, z)`` of :func:`phi`); leading axes form an ensemble.

    * ``bracket(A, X) = -(A x_L X)`` per particle (vector form of
      :math:`[\varphi(a), \varphi(x)]`);
    * ``bracket_and_triple(B, X)`` also returns ``2 (B ._L X) B - (B ._L B) X``, the vector form
      of :math:`\varphi(b)\varphi(x)\varphi(b)`;
    * ``casimirs(W)``: :math:`w_i \cdot_L w_i = x_i^2 + y_i^2 - z_i^2` per particle
      (:math:`= -\det\varphi(w_i)`), shape ``(*batch, N)``; their drift is measured relative to
      the Euclidean :math:`|w_i|^2`, the size of the rounding errors;
    * ``inner``: the Euclidean dot product (half the Frobenius pairing of the matrices);
    * ``dagger(g) = L g`` (vector form of :math:`\varphi(g)^T`).

    Parameters
    ----------
    N : int
        Number of particles.
    """

    name_template = "(R^3, x_L)^{N}"

    def bracket(self, A: Array, X: Array) -> Array:
        r"""``-(A x_L X)`` per particle: the vector form of :math:`[\varphi(a), \varphi(x)]`."""
        return (-2.0 * L_DIAG) * cross(A, X)

    def bracket_and_triple(self, B: Array, X: Array) -> tuple[Array, Array]:
        r"""``(-(B x_L X), 2 (B._L X) B - (B._L B) X)`` per particle: the vector forms of
        :math:`[\varphi(b), \varphi(x)]` and :math:`\varphi(b)\varphi(x)\varphi(b)`."""
        BL = B * L_DIAG
        bx = np.einsum("...i,...i->...", BL, X)[..., None]
        bb = np.einsum("...i,...i->...", BL, B)[..., None]
        return (-2.0 * L_DIAG) * cross(B, X), 2.0 * bx * B - bb * X

    def dagger(self, G: Array) -> Array:
        r"""Vector form of the matrix transpose: :math:`\varphi(g)^T = \varphi(L g)`.

        Parameters
        ----------
        G : ndarray, shape (*batch, N, 3)
            Gradients (one vector per particle).

        Returns
        -------
        ndarray, shape (*batch, N, 3)
        """
        return np.asarray(G) * L_DIAG

    def casimirs(self, W: Array) -> Array:
        r""":math:`w_i \cdot_L w_i` for each particle, shape ``(*batch, N)``.

        Parameters
        ----------
        W : ndarray, shape (*batch, N, 3)
            Elements, one vector per particle.

        Returns
        -------
        ndarray, shape (*batch, N)
        """
        return dot_L(W, W)

    def to_matrix(self, W: Array) -> Array:
        """:func:`phi` per particle, shape ``(*batch, N, 2, 2)`` (a homomorphism for
        :meth:`bracket`, which is the matrix bracket of the images).

        Parameters
        ----------
        W : ndarray, shape (*batch, N, 3)
            Elements (or values of ``B``).
        """
        return phi(W)

    def from_matrix(self, M: Array) -> Array:
        """:func:`phi_inv` per particle (coordinates of the traceless part).

        Parameters
        ----------
        M : ndarray, shape (*batch, N, 2, 2)
            Real matrices, one per particle.

        Returns
        -------
        ndarray, shape (*batch, N, 3)
        """
        return phi_inv(M)

    def phi(self, W: ArrayLike) -> Array:
        """:func:`phi` applied to every particle: shape ``(*batch, N, 2, 2)``.

        Parameters
        ----------
        W : ndarray, shape (*batch, N, 3)
            Elements.
        """
        return phi(W)

    def __repr__(self) -> str:
        return f"<algebra {self.name} ~ sl(2,R)^{self.N}>"


def sl2_vectors(N: int = 1) -> SL2Vectors:
    r"""The space :math:`(\mathbb{R}^3, \times_L)^N` of ``N`` copies of
    :math:`\mathfrak{sl}(2,\mathbb{R})` in the coordinates of :func:`phi`, shape ``(N, 3)``."""
    return SL2Vectors(N)
