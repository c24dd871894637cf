r"""Compiled descriptions of ``B``: what a problem carries so that methods can run compiled loops.

A :class:`FastKernel` names a built-in family of maps ``B`` and its parameters. It does not
replace ``problem.B`` (the general NumPy path and every diagnostic still call ``B``); it tells
:meth:`IsoMP.advance <isoflow.IsoMP.advance>` and
:meth:`SphericalMidpoint.advance <isoflow.SphericalMidpoint.advance>` that the same map can be
evaluated inside a compiled (numba) time loop. The kernel **must describe exactly the same**
``B`` as ``problem.B``; the fast paths are tested against the NumPy path to ``1e-13``.

This module has no numba dependency: the compiled loops live in :mod:`isoflow._fast.dense`,
:mod:`isoflow._fast.spin` and :mod:`isoflow._fast.vortices` and are imported (and compiled,
or loaded from the cache) on first use.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["ElementwiseLinear", "FastKernel", "PairwiseVortex", "SpinNeighbourSum"]

Array = NDArray[Any]


@dataclass(frozen=True, eq=False)
class ElementwiseLinear:
    r"""``B(W) = C \circ W`` (entrywise product) with a fixed real ``n x n`` array ``C``, or
    :math:`B(W) = U\,\big(C \circ (U^\dagger W U)\big)\,U^\dagger` in a fixed unitary frame.

    Covers the generalized rigid body (:math:`C_{ij} = -(d_i + d_j)/2` on
    :math:`\mathfrak{so}(n)`) and the Brockett flow :math:`B(W) = [N, W]`: with
    :math:`N = U \operatorname{diag}(\nu) U^\dagger` (``U = I`` when ``N`` is diagonal),
    :math:`[N, W] = U\,\big(C \circ (U^\dagger W U)\big)\,U^\dagger` with
    :math:`C_{ij} = \nu_i - \nu_j`. ``B`` lies in the normalizer when ``C`` is symmetric on the
    skew spaces :math:`\mathfrak{so}(n), \mathfrak{u}(n)` and antisymmetric on ``Sym(n)``,
    ``Herm(n)``.

    IsoMP commutes with the unitary change of frame :math:`W \mapsto U^\dagger W U` (it maps
    ``V``, the normalizer and every iterate of the step's fixed-point iteration to their
    counterparts), so the compiled loops run in the frame where ``B`` is entrywise and map
    the results back: the same steps and iterates up to rounding.

    Parameters
    ----------
    coeff : array_like, shape (n, n)
        The real coefficients ``C``.
    frame : array_like, shape (n, n), optional
        The unitary (orthogonal, for real spaces) ``U``; ``None`` means ``U = I``.
    """

    coeff: Array = field()
    frame: Array | None = None

    def __post_init__(self) -> None:
        c = np.ascontiguousarray(np.asarray(self.coeff, dtype=np.float64))
        if c.ndim != 2 or c.shape[0] != c.shape[1]:
            raise ValueError(f"ElementwiseLinear: coeff must be square, got shape {c.shape}")
        c.setflags(write=False)
        object.__setattr__(self, "coeff", c)
        if self.frame is None:
            return
        U = np.asarray(self.frame)
        if U.dtype.kind not in "fc":
            U = U.astype(np.float64)
        U = np.ascontiguousarray(U)
        if U.shape != c.shape:
            raise ValueError(
                f"ElementwiseLinear: frame must have the shape {c.shape} of coeff, got {U.shape}"
            )
        if not np.all(np.isfinite(U)):
            raise ValueError("ElementwiseLinear: frame has non-finite entries")
        gap = float(np.max(np.abs(U.conj().T @ U - np.eye(U.shape[0]))))
        if not gap <= 1e-12 * U.shape[0]:
            raise ValueError(f"ElementwiseLinear: frame is not unitary (|U^H U - I| = {gap:.2e})")
        U.setflags(write=False)
        object.__setattr__(self, "frame", U)

    def evaluate(self, W: ArrayLike) -> Array:
        """``C * W``, or ``U (C * (U^H W U)) U^H`` with a frame (NumPy), for checks."""
        Wa = np.asarray(W)
        if self.frame is None:
            return self.coeff * Wa
        U = self.frame
        Uh = U.conj().T
        return U @ (self.coeff * (Uh @ Wa @ U)) @ Uh


@dataclass(frozen=True)
class SpinNeighbourSum:
    r"""``B_i(w) = c\,(w_{i-1} + w_{i+1})`` on :math:`(\mathbb{R}^3,\times)^N`, periodic.

    The Heisenberg chain is ``c = -1`` (:math:`B_i = -\nabla_i H`,
    :math:`H = \sum_i w_i\cdot w_{i+1}`).

    Parameters
    ----------
    coupling : float
        The factor ``c``.
    """

    coupling: float = -1.0

    def evaluate(self, W: ArrayLike) -> Array:
        """``c (w_{i-1} + w_{i+1})`` over the particle axis (NumPy), for checks."""
        Wa = np.asarray(W, dtype=np.float64)
        return self.coupling * (np.roll(Wa, 1, axis=-2) + np.roll(Wa, -1, axis=-2))


#: The two geometries of :class:`PairwiseVortex`.
VortexGeometry = Literal["sphere", "hyperbolic"]
_VORTEX_COEFFICIENT = {"sphere": 1.0 / (4.0 * np.pi), "hyperbolic": -1.0 / np.pi}


@dataclass(frozen=True, eq=False)
class PairwiseVortex:
    r"""The pairwise point-vortex field on :math:`(\mathbb{R}^3,\times)^N` or
    :math:`(\mathbb{R}^3,\times_L)^N`:

    .. math::

        B_i(w) = c \sum_{j \ne i} \Gamma_j\, f(w_i \cdot w_j)\, w_j ,
        \qquad i = 1, \dots, N,

    with, for ``geometry``

    * ``"sphere"`` (point vortices on the unit sphere,
      :func:`~isoflow.models.sphere_vortices`, on ``so3_vectors(N)``): the Euclidean dot
      :math:`a \cdot b = a_1 b_1 + a_2 b_2 + a_3 b_3`, :math:`f(D) = 1/(1 - D)` and
      :math:`c = 1/(4\pi)`;
    * ``"hyperbolic"`` (point vortices on the hyperboloid,
      :func:`~isoflow.models.hyperbolic_vortices`, on ``sl2_vectors(N)``): the Lorentzian dot
      :math:`a \cdot_L b = a_1 b_1 + a_2 b_2 - a_3 b_3`,
      :math:`f(D) = 1/(D^2 - 1)`, evaluated as :math:`1/((D - 1)(D + 1))`, and
      :math:`c = -1/\pi`.

    The pair factor :math:`f(w_i \cdot w_j)` is symmetric in ``i, j``; the compiled loops
    compute it once per pair (:math:`N(N-1)/2` divisions per evaluation of ``B``).

    Parameters
    ----------
    circulations : array_like, shape (N,)
        The vortex strengths :math:`\Gamma_j`, real and finite (stored as a read-only
        ``float64`` copy).
    geometry : {"sphere", "hyperbolic"}
        Which dot product, pair function ``f`` and constant ``c``.

    Raises
    ------
    ValueError
        ``circulations`` not a non-empty real finite vector, or an unknown ``geometry``.
    """

    circulations: Array = field()
    geometry: VortexGeometry = field()

    def __post_init__(self) -> None:
        if not isinstance(self.geometry, str) or self.geometry not in _VORTEX_COEFFICIENT:
            raise ValueError(
                f"PairwiseVortex: geometry must be 'sphere' or 'hyperbolic', got {self.geometry!r}"
            )
        raw = np.asarray(self.circulations)
        if raw.dtype.kind not in "iuf":
            raise ValueError(
                f"PairwiseVortex: circulations must be real numbers, got dtype {raw.dtype}"
            )
        g = np.array(raw, dtype=np.float64, copy=True)
        if g.ndim != 1 or g.shape[0] < 1:
            raise ValueError(
                f"PairwiseVortex: circulations must have shape (N,) with N >= 1, got {g.shape}"
            )
        if not np.all(np.isfinite(g)):
            raise ValueError(f"PairwiseVortex: circulations must be finite, got {g}")
        g.setflags(write=False)
        object.__setattr__(self, "circulations", g)

    @property
    def N(self) -> int:
        """Number of vortices."""
        return int(self.circulations.shape[0])

    @property
    def coefficient(self) -> float:
        r"""The constant ``c``: :math:`1/(4\pi)` on the sphere, :math:`-1/\pi` hyperbolic."""
        return _VORTEX_COEFFICIENT[self.geometry]

    def evaluate(self, W: ArrayLike) -> Array:
        """``B(W)`` for ``W`` of shape ``(*batch, N, 3)`` (NumPy), for checks."""
        Wa = np.asarray(W, dtype=np.float64)
        N = self.N
        if Wa.ndim < 2 or Wa.shape[-2:] != (N, 3):
            raise ValueError(f"PairwiseVortex: W must have shape (*batch, {N}, 3), got {Wa.shape}")
        if self.geometry == "sphere":
            D = np.einsum("...ik,...jk->...ij", Wa, Wa)
            den = 1.0 - D
        else:
            D = np.einsum("...ik,...jk->...ij", Wa * np.array([1.0, 1.0, -1.0]), Wa)
            den = (D - 1.0) * (D + 1.0)
        off = ~np.eye(N, dtype=bool)
        K = np.where(off, self.circulations / np.where(off, den, 1.0), 0.0)
        return self.coefficient * np.einsum("...ij,...jk->...ik", K, Wa)


#: The compiled descriptions a problem may carry.
FastKernel = ElementwiseLinear | SpinNeighbourSum | PairwiseVortex
