r"""The stochastic IsoMP's compiled stage: IsoMP's, with the noise added to ``B``.

One fixed-point iteration for the stage ``X`` of a step of size ``h`` with the step's increments
:math:`\Delta\beta` (the unit's step data ``sd``, :class:`isoflow.StochasticIsoMP`):

.. math::

    \tilde B = B(X) + \tfrac1h \Big(\sum_i \Delta\beta_i\, \Xi_i
        + \sum_{p, a} \sigma_p\, \Delta\beta_{p a}\, e_{p a}\Big), \qquad
    G(X) = \Pi\big(W + \tfrac h2 [\tilde B, X] + \tfrac{h^2}{4} \tilde B X \tilde B\big),

and :math:`W_{k+1} = \Pi_V(W + h [\tilde B, X])`: IsoMP's blocks on every layout, with one
generic term in between. The fields are constant, so :func:`begin` forms the step's noise term
once per solve (:func:`add_noise`, in the unit's own layout, into the last scratch row) and
each iteration adds that row to ``B``. The noise is prepared once per run by
:func:`noise_params` (the method's parameters ``mp``):

* ``fields`` ``(m, S)``: the constant fields :math:`\Xi_i` mapped by the layout as a state
  (into a kernel's frame, the spin chain's ``(3, N)`` layout, every lane of a unit);
* ``site_pos`` ``(3P,)``, ``site_amp`` ``(3P,)``: where the entry ``(p, a)`` of the site noise
  sits in the unit, and :math:`\sigma_p`.

A unit of ``L`` lanes interleaves its members innermost (entry ``e`` of the flat buffer belongs
to lane ``e % L``), as :mod:`isoflow._compiled.lanes` lays them out; site noise runs on layouts
of one member per unit.

On large dense states (the BLAS layout) the noise is added to ``B`` before IsoMP's own BLAS
iteration (:func:`iterate_tiles`, :func:`iterate_planar`: the triangular product, real planes
with 3M products from ``n = 128``), so an iteration of the stochastic step costs what one of
IsoMP's does.
"""

from __future__ import annotations

from typing import Any

import numba
import numpy as np

from ...noise import TransportNoise
from .. import blocks, dense_planar, dense_tiles
from ..layout import Layout

__all__ = [
    "NWORK",
    "add_noise",
    "begin",
    "iterate",
    "iterate_planar",
    "iterate_tiles",
    "noise_params",
]

#: Scratch rows per unit: ``B``, ``B X B`` and the step's noise term (the last row).
NWORK = 3


@numba.njit(cache=True, inline="always")
def add_noise(lay, mp, sd, h, B):  # type: ignore[no-untyped-def]
    r"""``B += (1/h) (sum_i sd[q, i] fields[i] + site noise)`` per lane ``q`` of the unit."""
    fields, site_pos, site_amp = mp
    m = fields.shape[0]
    L = blocks.lanes(lay)
    inv = 1.0 / h
    S = B.shape[0]
    for i in range(m):
        Fi = fields[i]
        for e0 in range(0, S, L):  # entry e0 + q belongs to lane q
            for q in range(L):
                B[e0 + q] += (sd[q, i] * inv) * Fi[e0 + q]
    row = sd[0]
    for j in range(site_pos.shape[0]):
        B[np.uint64(site_pos[j])] += (row[np.uint64(m + j)] * inv) * site_amp[j]


@numba.njit(cache=True)
def begin(f, fargs, lay, mp, sd, W, work, h):  # type: ignore[no-untyped-def]
    r"""The step's noise term :math:`\tfrac1h (\sum_i \Delta\beta_i \Xi_i + \dots)` into the
    last scratch row, once per solve: the fields are constant, so an iteration adds one row
    instead of summing ``m`` fields (the rigid body's so(10) has 45)."""
    N = work[work.shape[0] - 1]
    for e in range(N.shape[0]):
        N[e] = 0.0
    add_noise(lay, mp, sd, h, N)


@numba.njit(cache=True, inline="always")
def _add_term(work, B):  # type: ignore[no-untyped-def]
    """``B += `` the noise term :func:`begin` left in the last scratch row."""
    N = work[work.shape[0] - 1]
    for e in range(B.shape[0]):
        B[e] += N[e]


@numba.njit(cache=True)
def iterate(f, fargs, lay, mp, sd, W, X, G, aux, work, h, rr):  # type: ignore[no-untyped-def]
    """``G = G(X)`` with the step's noise (the layout's stage map for ``B~``); ``aux`` the
    bracket the finish adds; ``rr`` per lane."""
    B = work[0]
    T = work[1]
    blocks.evaluate_B(lay, f, fargs, X, B)
    _add_term(work, B)
    blocks.stage_map(lay, W, h, B, X, G, aux, T, rr)


@numba.njit(cache=True)
def iterate_tiles(f, fargs, lay, mp, sd, W, X, G, aux, work, h, rr):  # type: ignore[no-untyped-def]
    """IsoMP's BLAS-tile iteration (:func:`isoflow._compiled.dense_tiles.iterate`) on
    ``B~(X)``: ``aux`` receives ``P = B~ X``, as that stage's finish reads it."""
    n = lay.n
    f(X.reshape((n, n)), work[0].reshape((n, n)), *fargs)
    _add_term(work, work[0])
    dense_tiles.iterate_from_B(lay, W, X, G, aux, work, h, rr)


@numba.njit(cache=True)
def iterate_planar(f, fargs, lay, mp, sd, W, X, G, aux, work, h, rr):  # type: ignore[no-untyped-def]
    """IsoMP's iteration in real planes with 3M products
    (:func:`isoflow._compiled.dense_planar.iterate`) on ``B~(X)``."""
    n = lay.n
    f(X.reshape((n, n)), work[0].reshape((n, n)), *fargs)
    _add_term(work, work[0])
    dense_planar.iterate_from_B(lay, W, X, G, aux, work, h, rr)


def noise_params(
    method: Any, problem: Any, layout: Layout, steps: tuple[float, ...]
) -> tuple[Any, ...]:
    """``(fields, site_pos, site_amp)`` of the problem's noise in ``layout``'s units (see the
    module docstring); empty arrays without noise. The step lengths ``steps`` are not read
    (the increments are the step data)."""
    alg = problem.algebra
    noise: TransportNoise | None = problem.noise
    probe = layout.to_units(np.zeros((1, *alg.shape), dtype=alg.dtype))
    S, dt = probe.shape[1], probe.dtype
    L = layout.lanes
    m = 0 if noise is None else int(noise.count or 0)
    if noise is not None and m and not isinstance(noise.fields, np.ndarray):
        raise NotImplementedError("state-dependent noise fields run on the NumPy path")
    fields = np.zeros((m, S), dtype=dt)
    for i in range(m):  # each field in every lane of a unit, mapped as a state
        Fi = np.asarray(noise.fields[i], dtype=alg.dtype)  # type: ignore[union-attr,index]
        fields[i] = layout.to_units(np.broadcast_to(Fi, (L, *alg.shape)).copy())[0]
    P = 0 if noise is None else noise.particles(alg)
    site_pos = np.zeros(3 * P, dtype=np.int64)
    site_amp = np.zeros(3 * P)
    if P:
        assert noise is not None
        where = layout.to_units(np.arange(3 * P, dtype=np.float64).reshape(1, P, 3))[0]
        site_pos[where.astype(np.int64)] = np.arange(S)
        site_amp[:] = np.repeat(noise.site_amplitudes(alg), 3)
    return fields, site_pos, site_amp


def compiled_noise(problem: Any) -> bool:
    """Whether the problem's noise runs compiled (constant fields, site noise)."""
    noise = problem.noise
    return noise is None or not noise.count or isinstance(noise.fields, np.ndarray)
