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
    r"""``B(W) = C \circ W`` (entrywise product) with a fixed real ``n x n`` array ``C``.

    Covers the generalized rigid body (:math:`C_{ij} = -(d_i + d_j)/2` on
    :math:`\mathfrak{so}(n)`) and the Brockett flow with diagonal
    :math:`N = \operatorname{diag}(\nu)` (:math:`[N, W]_{ij} = (\nu_i - \nu_j) W_{ij}` on
    ``Sym(n)``/``Herm(n)``). ``B`` lies in the normalizer when ``C`` is symmetric on the skew
    spaces :math:`\mathfrak{so}(n), \mathfrak{u}(n)` and antisymmetric on ``Sym(n)``,
    ``Herm(n)``.

    Parameters
    ----------
    coeff : array_like, shape (n, n)
        The real coefficients ``C``.
    """

    coeff: Array = field()

    def __post_init__(self) -> None:
        c = np.ascontiguousarray(np.asarray(self.coeff, dtype=np.float64))
        if c.ndim != 2 or c.shape[0] != c.shape[1]:
            raise ValueError(f"ElementwiseLinear: coeff must be square, got shape {c.shape}")
        c.setflags(write=False)
        object.__setattr__(self, "coeff", c)

    def evaluate(self, W: ArrayLike) -> Array:
        """``C * W`` (NumPy), for checks."""
        return self.coeff * np.asarray(W)


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
