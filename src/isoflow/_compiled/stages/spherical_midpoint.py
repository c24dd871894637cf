r"""The spherical midpoint's compiled stage, written once against the layout blocks.

:class:`isoflow.SphericalMidpoint` on :math:`(\mathbb{R}^3,\times)^N` iterates on the plain
average ``M`` (McLachlan, Modin and Verdier):

.. math::

    m_i = \sqrt{|w_i|\,|2M_i - w_i|}\; M_i/|M_i|, \qquad
    G_i = w_i + \tfrac h2\, B_i(m) \times m_i, \qquad w_{k+1} = w + h\, B(m) \times m .

Layouts that provide ``spherical_point`` (the particles on :math:`(\mathbb{R}^3,\times)`, point
vortices on the sphere, spin chains) run it. Two scratch rows: ``B(m)`` and ``m``. Named
specialization: the fused sweeps on spin chains (:mod:`isoflow._compiled.spin_chain`,
benchmark 5).
"""

from __future__ import annotations

import numba

from .. import blocks

__all__ = ["NWORK", "finish", "iterate"]

#: Scratch rows per unit: ``B(m)`` and ``m``.
NWORK = 2


@numba.njit(cache=True)
def iterate(f, fargs, lay, mp, sd, W, X, G, aux, work, h, rr):  # type: ignore[no-untyped-def]
    """``G = G(M)`` for the average ``M = X``; ``aux = B(m) x m``."""
    B = work[0]
    mid = work[1]
    blocks.spherical_point(lay, W, X, mid)
    blocks.evaluate_B(lay, f, fargs, mid, B)
    blocks.bracket(lay, B, mid, aux)
    blocks.stage_update1(lay, W, 0.5 * h, aux, G, X, rr)


@numba.njit(cache=True)
def finish(f, fargs, lay, mp, sd, W, X, aux, work, h, E, Wn, fin):  # type: ignore[no-untyped-def]
    """``Wn = W + h B(m) x m`` from the last iteration."""
    blocks.advance_state(lay, W, h, aux, E, Wn, fin)
