r"""Reproducible Gaussian increments keyed by (seed, member, step).

:func:`gaussian_increments` gives the increments of the steps ``k0 + 1 .. k0 + nsteps`` of
ensemble members as one array ``(nsteps, members, dims)``. They come from numpy's
counter-based generator :class:`numpy.random.Philox` (Philox4x64): member ``m`` of a run
seeded ``seed`` draws with the key ``(seed, m)``; normals ``4 j .. 4 j + 3`` of step ``k`` are
the Box–Muller transform of the four 64-bit words of the block at the counter
``(k, j, stream, 0)`` (a fixed number of raw draws per step, so consecutive steps are
consecutive blocks and a chunk of steps is one call per block column). A step's increments
are therefore a function of ``(seed, stream, member, step)`` alone: a run, its resume after a
kill, an ensemble cut into chunks or tasks, and any number of threads draw exactly the same
numbers, bit for bit.
``stream`` separates independent uses of one seed (a stochastic forcing draws from stream
:data:`isoflow.splitting.FORCING_STREAM`).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._errors import ParameterError

__all__ = ["gaussian_increments"]


def gaussian_increments(
    seed: int, members: ArrayLike, k0: int, nsteps: int, dims: int, h: float, *, stream: int = 0
) -> NDArray[np.float64]:
    r"""Standard normal draws times :math:`\sqrt h`, shape ``(nsteps, len(members), dims)``.

    Row ``s`` of member ``members[i]`` is step ``k0 + 1 + s``; a negative member (the padding
    lanes of a compiled unit) gets zeros.

    Raises
    ------
    ParameterError
        A seed or stream that is not an integer ``>= 0``, or a negative ``h``.
    """
    for name, v in (("seed", seed), ("stream", stream)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
            raise ParameterError(f"noise: {name} must be an integer >= 0, got {v!r}")
    if not (math.isfinite(h) and h >= 0):
        raise ParameterError(f"noise: h must be finite and >= 0, got {h!r}")
    ids = np.asarray(members, dtype=np.int64).reshape(-1)
    n, d = int(nsteps), int(dims)
    out = np.zeros((n, ids.size, d))
    if n == 0 or d == 0:
        return out
    scale = math.sqrt(h)
    for i, m in enumerate(ids):
        if m < 0:
            continue
        key = np.array([int(seed), int(m)], dtype=np.uint64)
        for j in range(-(-d // 4)):
            counter = np.array([int(k0) + 1, j, int(stream), 0], dtype=np.uint64)
            raw = np.random.Philox(key=key, counter=counter).random_raw(4 * n).reshape(n, 4)
            z = _box_muller(raw)
            w = min(4, d - 4 * j)
            out[:, i, 4 * j : 4 * j + w] = z[:, :w] * scale
    return out


def _box_muller(raw: NDArray[np.uint64]) -> NDArray[np.float64]:
    """Four standard normals per row of four 64-bit words (two Box–Muller pairs)."""
    u = ((raw >> np.uint64(11)).astype(np.float64) + 1.0) * 2.0**-53  # in (0, 1]
    r0 = np.sqrt(-2.0 * np.log(u[:, 0]))
    r1 = np.sqrt(-2.0 * np.log(u[:, 2]))
    a0 = 2.0 * np.pi * u[:, 1]
    a1 = 2.0 * np.pi * u[:, 3]
    return np.stack([r0 * np.cos(a0), r0 * np.sin(a0), r1 * np.cos(a1), r1 * np.sin(a1)], axis=1)
