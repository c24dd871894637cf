r"""Compiled descriptions of ``B``: what a problem carries so that methods can run compiled loops.

A :class:`FastKernel` names a built-in family of maps ``B`` and its parameters. It does not
replace ``problem.B`` (the general NumPy path and every diagnostic still call ``B``); it tells
:meth:`IsoMP.advance <isoflow.IsoMP.advance>` and
:meth:`SphericalMidpoint.advance <isoflow.SphericalMidpoint.advance>` that the same map can be
evaluated inside a compiled (numba) time loop. The kernel **must describe exactly the same**
``B`` as ``problem.B``; the fast paths are tested against the NumPy path to ``1e-13``.

This module has no numba dependency: the compiled loops live in :mod:`isoflow._fast.dense`
and :mod:`isoflow._fast.spin` and are imported (and compiled, or loaded from the cache) on
first use.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["ElementwiseLinear", "FastKernel", "SpinNeighbourSum"]

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


#: The compiled descriptions a problem may carry.
FastKernel = ElementwiseLinear | SpinNeighbourSum
