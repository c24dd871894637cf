r"""The compact form :math:`(\mathbb{R}^3, \times)^N` of :math:`\mathfrak{so}(3)^N`: spin systems.

The hat map :math:`\hat a\, b = a \times b`,

.. math::

    \hat a = \begin{pmatrix} 0 & -a_3 & a_2 \\ a_3 & 0 & -a_1 \\ -a_2 & a_1 & 0 \end{pmatrix},

is a Lie algebra isomorphism :math:`(\mathbb{R}^3, \times) \to \mathfrak{so}(3)`:
:math:`[\hat a, \hat b] = \widehat{a \times b}`. The two products IsoMP needs are therefore

* the bracket :math:`[B, X] \leftrightarrow b \times x`;
* the triple product :math:`\hat b \hat x \hat b = -(b \cdot x)\, \hat b \leftrightarrow
  -(b \cdot x)\, b`,

so that :class:`~isoflow.IsoMP` on :class:`SpinVectors` *is* the matrix method on
:math:`\mathfrak{so}(3)` (for every particle at once), at the cost of a few vector operations.
Written out, one step solves
:math:`x = w_k + \tfrac h2\, b \times x - \tfrac{h^2}{4} (b\cdot x)\, b` with
:math:`b = B(x)` and sets :math:`w_{k+1} = w_k + h\, b \times x`; equivalently
:math:`w_k = x + \tfrac h2\, x \times b + \tfrac{h^2}{4}(b\cdot x)\,b` (the paper prints the
:math:`h^2` term with the wrong sign; that variant is not Lie–Poisson).

Pairing convention
------------------
Vectors are paired by the Euclidean dot product (:meth:`Algebra.inner`), which is *half* the
Frobenius pairing of the hat matrices: :math:`\operatorname{Tr}(\hat a^T \hat b) = 2\, a\cdot b`.
The dagger (:meth:`SpinVectors.dagger`) is the vector form of the transpose,
:math:`\hat g^T = -\hat g \leftrightarrow -g`. Hence
:meth:`IsospectralProblem.from_hamiltonian <isoflow.IsospectralProblem.from_hamiltonian>` with
the *Euclidean* gradient :math:`\nabla H` gives :math:`B = -\nabla H` and the flow

.. math:: \dot w_i = -\nabla_i H \times w_i = w_i \times \nabla_i H,

the usual rigid-body/spin convention, with Poisson tensor :math:`P(w) = \operatorname{diag}
(\hat w_1, \dots, \hat w_N)`, :math:`\dot w = P(w) \nabla H`. (The same ``H`` written on
:math:`3\times 3` matrices with the Frobenius pairing runs at half this speed.)
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._vectors import ParticleVectors

__all__ = ["SpinVectors", "cross", "dot", "hat", "so3_vectors", "vee"]

Array = NDArray[Any]


def cross(a: Array, b: Array) -> Array:
    r"""Cross product over the last axis (length 3), broadcasting over the others.

    The same as :func:`numpy.cross` on the last axis, about twice as fast on small arrays.
    """
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def dot(a: Array, b: Array) -> Array:
    """Euclidean dot product over the last axis, broadcasting over the others."""
    return np.einsum("...i,...i->...", a, b)


def hat(w: ArrayLike) -> Array:
    r"""The hat map :math:`\mathbb{R}^3 \to \mathfrak{so}(3)`, :math:`\hat w\, v = w \times v`.

    Parameters
    ----------
    w : array_like, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., 3, 3)
        Skew-symmetric matrices with :math:`[\hat a, \hat b] = \widehat{a\times b}`.
    """
    w = np.asarray(w, dtype=np.float64)
    z = np.zeros(w.shape[:-1])
    w1, w2, w3 = w[..., 0], w[..., 1], w[..., 2]
    rows = [
        np.stack([z, -w3, w2], axis=-1),
        np.stack([w3, z, -w1], axis=-1),
        np.stack([-w2, w1, z], axis=-1),
    ]
    return np.stack(rows, axis=-2)


def vee(W: ArrayLike) -> Array:
    r"""Inverse of :func:`hat`: the vector of the skew part of ``W``, shape ``(..., 3)``.

    For a skew-symmetric ``W`` this is exact; otherwise it returns the vector of
    :math:`(W - W^T)/2`.
    """
    W = np.asarray(W, dtype=np.float64)
    return 0.5 * np.stack(
        [W[..., 2, 1] - W[..., 1, 2], W[..., 0, 2] - W[..., 2, 0], W[..., 1, 0] - W[..., 0, 1]],
        axis=-1,
    )


class SpinVectors(ParticleVectors):
    r""":math:`(\mathbb{R}^3, \times)^N \cong \mathfrak{so}(3)^N`: ``N`` spins, shape ``(N, 3)``.

    Every real ``(N, 3)`` array is an element (``project`` only converts to ``float64``); the
    algebra is its own normalizer. Particle ``i`` is row ``i``; leading axes before ``(N, 3)``
    form an ensemble.

    * ``bracket(A, X)[i] = A[i] x X[i]`` (vector form of :math:`[\hat a, \hat x]`);
    * ``bracket_and_triple(B, X)`` returns ``(B x X, -(B.X) B)`` per particle (vector form of
      :math:`([\hat b, \hat x], \hat b \hat x \hat b)`);
    * ``casimirs(W)``: :math:`|w_i|^2` per particle, shape ``(*batch, N)``;
    * ``inner``: the Euclidean dot product over all particles (half the Frobenius pairing of
      the hat matrices, see the module docstring for what this means for Hamiltonians);
    * ``dagger(g) = -g`` (vector form of :math:`\hat g^T`).

    Parameters
    ----------
    N : int
        Number of particles.
    """

    name_template = "(R^3, x)^{N}"

    @property
    def closed_form_stage(self) -> bool:  # type: ignore[override]
        """``True``: :meth:`solve_stage` is this space's stage, unless a subclass changes the
        products it is derived from (``bracket_and_triple``)."""
        return type(self).bracket_and_triple is SpinVectors.bracket_and_triple

    def bracket(self, A: Array, X: Array) -> Array:
        r"""``A x X`` per particle: the vector form of :math:`[\hat a, \hat x]`."""
        return cross(A, X)

    def bracket_and_triple(self, B: Array, X: Array) -> tuple[Array, Array]:
        r"""``(B x X, -(B.X) B)`` per particle: :math:`[\hat b,\hat x]` and
        :math:`\hat b \hat x \hat b = -(b\cdot x)\hat b` in vector form."""
        return cross(B, X), -dot(B, X)[..., None] * B

    def solve_stage(self, W: Array, B: Array, h: float) -> tuple[Array, Array]:
        r"""IsoMP's stage of every particle for the field ``B`` in closed form, and the bracket
        the finish adds.

        With :math:`u_i = \tfrac h2 b_i`, the stage equation
        :math:`\hat w_i = (I - \hat u_i)\,\hat x_i\,(I + \hat u_i)` reads
        :math:`w_i = x_i - u_i \times x_i + (u_i \cdot x_i)\, u_i`; the inverse of this
        linear map is :math:`(I + \hat u_i) / (1 + |u_i|^2)`, so

        .. math::

            x_i = \frac{w_i + u_i \times w_i}{1 + |u_i|^2}, \qquad
            C_i = b_i \times x_i,

        and :math:`w_i + h C_i` is the Cayley rotation of :math:`w_i` by :math:`u_i`: the
        finish keeps every :math:`|w_i|` whatever the field. IsoMP then iterates
        :math:`X \leftarrow X(B(X))`, whose contraction comes from how ``B`` depends on
        ``X`` only, not from the particle's own rotation (spin chains and lattices, noisy or
        not: a fifth to a third fewer iterations than the plain map, 30-40% fewer with site
        noise).

        Parameters
        ----------
        W : ndarray, shape (*batch, N, 3)
            The step's state.
        B : ndarray, shape (*batch, N, 3)
            The field.
        h : float
            The step size.

        Returns
        -------
        X, C : ndarray, shape (*batch, N, 3)
        """
        u = (0.5 * h) * B
        k = 1.0 / (1.0 + dot(u, u))
        X = k[..., None] * (W + cross(u, W))
        return X, cross(B, X)

    def solve_stage_jvp(self, W: Array, B: Array, dB: Array, h: float) -> Array:
        r"""The derivative of :meth:`solve_stage`'s ``X`` along ``dB``:
        :math:`k\, du \times w - 2 k^2 (u \cdot du)(w + u \times w)`,
        :math:`k = 1/(1 + |u|^2)`, :math:`du = \tfrac h2 dB`.

        Parameters
        ----------
        W, B, dB : ndarray, shape (*batch, N, 3)
            The step's state, the field and its direction.
        h : float
            The step size.

        Returns
        -------
        ndarray, shape (*batch, N, 3)
        """
        u = (0.5 * h) * B
        du = (0.5 * h) * dB
        k = 1.0 / (1.0 + dot(u, u))
        return k[..., None] * cross(du, W) - (2.0 * k * k * dot(u, du))[..., None] * (
            W + cross(u, W)
        )

    def dagger(self, G: Array) -> Array:
        r"""Vector form of the matrix transpose: :math:`\hat g^T = -\hat g`, so ``-G``.

        Parameters
        ----------
        G : ndarray, shape (*batch, N, 3)
            Gradients (one vector per particle).

        Returns
        -------
        ndarray, shape (*batch, N, 3)
        """
        return -np.asarray(G)

    def casimirs(self, W: Array) -> Array:
        r""":math:`|w_i|^2` for each particle, shape ``(*batch, N)``.

        Parameters
        ----------
        W : ndarray, shape (*batch, N, 3)
            Spins.

        Returns
        -------
        ndarray, shape (*batch, N)
        """
        return dot(W, W)

    def to_matrix(self, W: Array) -> Array:
        """:func:`hat` per particle, shape ``(*batch, N, 3, 3)`` (a homomorphism for
        :meth:`bracket`).

        Parameters
        ----------
        W : ndarray, shape (*batch, N, 3)
            Spins (or values of ``B``).
        """
        return hat(W)

    def from_matrix(self, M: Array) -> Array:
        """:func:`vee` per particle (the vector of the skew part).

        Parameters
        ----------
        M : ndarray, shape (*batch, N, 3, 3)
            Matrices, one per particle.

        Returns
        -------
        ndarray, shape (*batch, N, 3)
        """
        return vee(M)

    def hat(self, W: ArrayLike) -> Array:
        """:func:`hat` applied to every particle: shape ``(*batch, N, 3, 3)``.

        Parameters
        ----------
        W : ndarray, shape (*batch, N, 3)
            Spins.
        """
        return hat(W)

    def __repr__(self) -> str:
        return f"<algebra {self.name} ~ so(3)^{self.N}>"


def so3_vectors(N: int = 1) -> SpinVectors:
    r"""The space :math:`(\mathbb{R}^3, \times)^N` of ``N`` spins, states of shape ``(N, 3)``.

    Examples
    --------
    A user-defined spin Hamiltonian (anisotropic coupling plus a field along ``z``), with its
    Euclidean gradient; the flow is :math:`\dot w_i = w_i \times \nabla_i H`:

    >>> import numpy as np, isoflow as iso
    >>> J = np.array([1.0, 1.0, 0.5])
    >>> def H(W):
    ...     return np.sum(J * W[..., 0, :] * W[..., 1, :], -1) + np.sum(W[..., 2], -1)
    >>> def grad(W):  # two spins: d/dw_0 = J w_1 + e_z, d/dw_1 = J w_0 + e_z
    ...     return J * W[..., ::-1, :] + np.array([0.0, 0.0, 1.0])
    >>> alg = iso.algebras.so3_vectors(2)
    >>> prob = iso.IsospectralProblem.from_hamiltonian(alg, H, grad)
    >>> w0 = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    >>> sol = iso.solve(prob, iso.IsoMP(), y0=w0, dt=0.1, t1=1.0)
    >>> bool(np.allclose(prob.vector_field(w0), np.cross(w0, grad(w0))))
    True
    """
    return SpinVectors(N)
