r"""The point-vortex layouts: :class:`~isoflow.PairwiseVortex` with its pair sum inlined.

The generic particle layout (:mod:`isoflow._compiled.particles`) calls the kernel's field
``f(X, B, *args)`` on ``(N, 3)`` views of the flat state. For a few vortices (the paper's three)
an iteration is a few dozen flops and that call costs as much again, so these layouts form
``B`` themselves (benchmark 7): the pair sum

.. math::

    B_i = c \sum_{j \ne i} \Gamma_j\, q(w_i \cdot w_j)\, w_j ,
    \qquad q(D) = \frac{1}{1 - D}\ \text{(sphere)}, \quad
    q(D) = \frac{1}{(D - 1)(D + 1)}\ \text{(hyperbolic, Lorentzian dot)},

in place on the flat state (:func:`isoflow._kernel_fields.pair_field`, the one statement of the
vortex fields, which the kernel's own fields use too). Everything else is the particle layouts'
blocks, so every method that runs on particles runs here with the same iterates.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numba
import numpy as np
from numpy.typing import NDArray

from .._kernel_fields import pair_field
from ..kernels import PairwiseVortex
from . import blocks
from .layout import Layout, member_layout
from .particles import provide_particle_blocks

__all__ = ["VortexHyperbolic", "VortexSphere", "vortex_layout"]


class VortexSphere(NamedTuple):
    r"""Point vortices on the sphere, :math:`(\mathbb{R}^3,\times)^N`: circulations and the
    field's coefficient ``c``."""

    N: int
    circ: NDArray[np.float64]
    c: float


class VortexHyperbolic(NamedTuple):
    r"""Point vortices on the hyperboloid, :math:`(\mathbb{R}^3,\times_L)^N`."""

    N: int
    circ: NDArray[np.float64]
    c: float


@numba.njit(cache=True, inline="always", error_model="numpy")
def _sphere_B(lay, f, fargs, X, B):  # type: ignore[no-untyped-def]
    pair_field(X, B, lay.circ, lay.c, lay.N, False)


@numba.njit(cache=True, inline="always", error_model="numpy")
def _hyperbolic_B(lay, f, fargs, X, B):  # type: ignore[no-untyped-def]
    pair_field(X, B, lay.circ, lay.c, lay.N, True)


blocks.provide(blocks.evaluate_B, VortexSphere)(_sphere_B)
blocks.provide(blocks.evaluate_B, VortexHyperbolic)(_hyperbolic_B)
provide_particle_blocks((VortexSphere,), (VortexHyperbolic,))


def vortex_layout(problem: Any, members: int) -> Layout | None:
    """The layout of a :class:`~isoflow.PairwiseVortex` run (its space is checked against the
    kernel with the problem), or ``None``."""
    kernel = problem.kernel
    if not isinstance(kernel, PairwiseVortex):
        return None
    alg = problem.algebra
    N = alg.shape[0]
    _, (circ, c) = kernel.field()
    circ = np.ascontiguousarray(circ, dtype=np.float64)
    rec = (VortexSphere if kernel.geometry == "sphere" else VortexHyperbolic)(N, circ, float(c))
    name = f"point vortices ({kernel.geometry}, pair sum inlined)"
    return member_layout(name, rec, alg.shape, np.float64)
