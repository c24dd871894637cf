r"""Fused stages for point vortices: :class:`~isoflow.PairwiseVortex` without a field call.

The generic particle stages (:mod:`isoflow._compiled.particles`) call the kernel's field
``f(X, B, *args)`` on ``(N, 3)`` views of the flat state. For a few vortices (the paper's three)
an iteration is a few dozen flops and those calls and views cost as much again, so this
kernel keeps a specialized evaluation (benchmark 7): the pair sum

.. math::

    B_i = c \sum_{j \ne i} \Gamma_j\, q(w_i \cdot w_j)\, w_j ,
    \qquad q(D) = \frac{1}{1 - D}\ \text{(sphere)}, \quad
    q(D) = \frac{1}{(D - 1)(D + 1)}\ \text{(hyperbolic, Lorentzian dot)},

is formed in place on the flat state (one pass over the pairs ``i < j``, each ``B_i`` summing
its terms in the order ``j = 0, 1, ...``, exactly as :func:`isoflow._kernel_fields.vortex_sphere`
and :func:`~isoflow._kernel_fields.vortex_hyperbolic` do), and the IsoMP or spherical-midpoint
update follows with the same formulas as the generic stages, so both give the same iterates.

``sp = (N,)``; ``fargs = (circulations, c)`` are the kernel's own field arguments.
"""

from __future__ import annotations

import numba

from .._kernel_fields import pair_field
from .particles import _put, _sl2, _so3, smm_update, spherical_point

__all__ = ["iterate_hyperbolic", "iterate_sphere", "iterate_sphere_smm"]


@numba.njit(cache=True, inline="always")
def _isomp(form, lorentz, fargs, sp, W, X, G, aux, work, half, quarter):  # type: ignore[no-untyped-def]
    N = sp[0]
    B = work[0]
    pair_field(X, B, fargs[0], fargs[1], N, lorentz)
    rr = 0.0
    for i in range(N):
        j = 3 * i
        x0, x1, x2 = X[j], X[j + 1], X[j + 2]
        c0, c1, c2, t0, t1, t2 = form(B[j], B[j + 1], B[j + 2], x0, x1, x2)
        g0 = W[j] + half * c0 + quarter * t0
        g1 = W[j + 1] + half * c1 + quarter * t1
        g2 = W[j + 2] + half * c2 + quarter * t2
        rr += _put(W, G, aux, j, c0, c1, c2, g0, g1, g2, x0, x1, x2)
    return rr


@numba.njit(cache=True, error_model="numpy")
def iterate_sphere(f, fargs, sp, W, X, G, aux, work, half, quarter):  # type: ignore[no-untyped-def]
    """One IsoMP iteration of vortices on the sphere, :math:`(\\mathbb{R}^3,\\times)^N`."""
    return _isomp(_so3, False, fargs, sp, W, X, G, aux, work, half, quarter)


@numba.njit(cache=True, error_model="numpy")
def iterate_hyperbolic(f, fargs, sp, W, X, G, aux, work, half, quarter):  # type: ignore[no-untyped-def]
    """One IsoMP iteration of vortices on the hyperboloid, :math:`(\\mathbb{R}^3,\\times_L)^N`."""
    return _isomp(_sl2, True, fargs, sp, W, X, G, aux, work, half, quarter)


@numba.njit(cache=True, error_model="numpy")
def iterate_sphere_smm(f, fargs, sp, W, X, G, aux, work, half, quarter):  # type: ignore[no-untyped-def]
    """One spherical-midpoint iteration of vortices on the sphere (``work[1]`` holds ``m``)."""
    N = sp[0]
    mid = work[1]
    spherical_point(W, X, mid, N)
    pair_field(mid, work[0], fargs[0], fargs[1], N, False)
    return smm_update(W, X, G, aux, work[0], mid, N, half)
