r"""IsoMP's compiled stage, written once against the layout blocks.

One fixed-point iteration for the stage ``X`` of a step of size ``h``
(:class:`isoflow.IsoMP`, Viviani's Theorem 1), with ``B = B(X)``:

.. math::

    G(X) = \Pi\big(W + \tfrac h2 [B, X] + \tfrac{h^2}{4} B X B\big), \qquad
    W_{k+1} = \Pi_V\big(W + h [B, X]\big)

with ``[B, X]`` of the accepted ``X`` (kept in ``aux`` by the last iteration): the layout's
:func:`~isoflow._compiled.blocks.stage_map`. On :math:`(\mathbb{R}^3,\times)^N` that block solves
each particle's stage for the field of the iterate in closed form,
:math:`g_i = (w_i + u_i \times w_i)/(1 + |u_i|^2)`, :math:`u_i = \tfrac h2 b_i` (the same fixed
point, fewer iterations: the particle's own linear part no longer slows the iteration), and the
finish adds :math:`h\, b_i \times g_i`, a rotation of :math:`w_i`. Two scratch rows: ``B`` and
``B X B``. Named specializations: the BLAS tiles on large dense states
(:mod:`isoflow._compiled.dense_tiles`, benchmarks 3, 10, 12) and the fused sweeps on spin chains
(:mod:`isoflow._compiled.spin_chain`, benchmarks 4, 5).
"""

from __future__ import annotations

import numba

from .. import blocks

__all__ = ["NWORK", "finish", "iterate"]

#: Scratch rows per unit: ``B`` and ``B X B``.
NWORK = 2


@numba.njit(cache=True)
def iterate(f, fargs, lay, mp, sd, W, X, G, aux, work, h, rr):  # type: ignore[no-untyped-def]
    r"""``G = G(X)``; ``aux`` the bracket the finish adds (``[B(X), X]``, or per particle
    ``B_i x G_i`` on :math:`(\mathbb{R}^3,\times)^N`); ``rr`` the squared residuals per lane."""
    B = work[0]
    T = work[1]
    blocks.evaluate_B(lay, f, fargs, X, B)
    blocks.stage_map(lay, W, h, B, X, G, aux, T, rr)


@numba.njit(cache=True)
def finish(f, fargs, lay, mp, sd, W, X, aux, work, h, E, Wn, fin):  # type: ignore[no-untyped-def]
    """``Wn = Pi_V(W + h [B, X])`` from the bracket of the last iteration."""
    blocks.advance_state(lay, W, h, aux, E, Wn, fin)
