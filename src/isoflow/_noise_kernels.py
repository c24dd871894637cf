r"""Compiled kernels of :mod:`isoflow.noise`: numpy's Philox4x64-10 and the normal quantile.

Imported on first use (importing :mod:`isoflow` does not load numba).

* :func:`philox_block` is the Philox4x64 bijection with ten rounds (Salmon, Moraes, Dror,
  Shaw, *Parallel random numbers: as easy as 1, 2, 3*, SC 2011), the generator behind
  :class:`numpy.random.Philox`: numpy's stream from ``Philox(key=k, counter=c)`` is
  ``philox_block(c + 1, k), philox_block(c + 2, k), ...`` (its counter is incremented before
  each block), which ``tests/test_noise.py`` checks bit for bit. A block is a pure function of
  its counter and key, so any block of any stream is computed without the ones before.
* :func:`normal_quantile` is Wichura's algorithm AS 241 (PPND16, *Appl. Statist.* 37 (1988)
  477-484), the inverse of the standard normal distribution function to about 1e-16 relative
  accuracy, compared with :func:`scipy.special.ndtri` in the tests.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from llvmlite import ir
from numba import types
from numba.extending import intrinsic

__all__ = ["fill_normals", "normal_quantile", "philox_block"]

_U = np.uint64
#: Philox4x64 multipliers and Weyl key increments (Random123).
_M0 = _U(0xD2E7470EE14C6C93)
_M1 = _U(0xCA5A826395121157)
_W0 = _U(0x9E3779B97F4A7C15)
_W1 = _U(0xBB67AE8584CAA73B)
_ROUNDS = 10
#: 2**-53: a 53-bit integer times this is a double in [0, 1).
_TWO53 = 1.0 / 9007199254740992.0


@intrinsic
def _mulhilo(typingctx, a, b):  # type: ignore[no-untyped-def]
    """``(hi, lo)`` of the 128-bit product of two uint64 (one widening multiply)."""
    sig = types.UniTuple(types.uint64, 2)(types.uint64, types.uint64)

    def codegen(context, builder, signature, args):  # type: ignore[no-untyped-def]
        wide = ir.IntType(128)
        p = builder.mul(builder.zext(args[0], wide), builder.zext(args[1], wide))
        lo = builder.trunc(p, ir.IntType(64))
        hi = builder.trunc(builder.lshr(p, ir.Constant(wide, 64)), ir.IntType(64))
        return context.make_tuple(builder, signature.return_type, (hi, lo))

    return sig, codegen


@numba.njit(cache=True, inline="always")
def philox_block(c0, c1, c2, c3, k0, k1):  # type: ignore[no-untyped-def]
    """The four uint64 words of Philox4x64-10 at counter ``(c0, c1, c2, c3)``, key
    ``(k0, k1)``."""
    for r in range(_ROUNDS):
        if r > 0:
            k0 = k0 + _W0
            k1 = k1 + _W1
        hi0, lo0 = _mulhilo(_M0, c0)
        hi1, lo1 = _mulhilo(_M1, c2)
        c0, c1, c2, c3 = hi1 ^ c1 ^ k0, lo1, hi0 ^ c3 ^ k1, lo0
    return c0, c1, c2, c3


@numba.njit(cache=True, inline="always")
def normal_quantile(p):  # type: ignore[no-untyped-def]
    """The standard normal quantile of ``0 < p < 1`` (AS 241)."""
    q = p - 0.5
    if abs(q) <= 0.425:
        r = 0.180625 - q * q
        num = (((((((r * 2509.0809287301226727 + 33430.575583588128105) * r
                    + 67265.770927008700853) * r + 45921.953931549871457) * r
                  + 13731.693765509461125) * r + 1971.5909503065514427) * r
                + 133.14166789178437745) * r + 3.387132872796366608)  # fmt: skip
        den = (((((((r * 5226.495278852545925 + 28729.085735721942674) * r
                    + 39307.89580009271061) * r + 21213.794301586595867) * r
                  + 5394.1960214247511077) * r + 687.1870074920579083) * r
                + 42.313330701600911252) * r + 1.0)  # fmt: skip
        return q * num / den
    r = p if q < 0.0 else 1.0 - p
    r = math.sqrt(-math.log(r))
    if r <= 5.0:
        r -= 1.6
        num = (((((((r * 7.7454501427834140764e-4 + 0.0227238449892691845833) * r
                    + 0.24178072517745061177) * r + 1.27045825245236838258) * r
                  + 3.64784832476320460504) * r + 5.7694972214606914055) * r
                + 4.6303378461565452959) * r + 1.42343711074968357734)  # fmt: skip
        den = (((((((r * 1.05075007164441684324e-9 + 5.475938084995344946e-4) * r
                    + 0.0151986665636164571966) * r + 0.14810397642748007459) * r
                  + 0.68976733498510000455) * r + 1.6763848301838038494) * r
                + 2.05319162663775882187) * r + 1.0)  # fmt: skip
    else:
        r -= 5.0
        num = (((((((r * 2.01033439929228813265e-7 + 2.71155556874348757815e-5) * r
                    + 0.0012426609473880784386) * r + 0.026532189526576123093) * r
                  + 0.29656057182850489123) * r + 1.7848265399172913358) * r
                + 5.4637849111641143699) * r + 6.6579046435011037772)  # fmt: skip
        den = (((((((r * 2.04426310338993978564e-15 + 1.4215117583164458887e-7) * r
                    + 1.8463183175100546818e-5) * r + 7.868691311456132591e-4) * r
                  + 0.0148753612908506148525) * r + 0.13692988092273580531) * r
                + 0.59983220655588793769) * r + 1.0)  # fmt: skip
    x = num / den
    return -x if q < 0.0 else x


@numba.njit(cache=True, inline="always")
def _uniform(x):  # type: ignore[no-untyped-def]
    """The open-interval uniform ``((x >> 11) + 1/2) 2^-53`` of a raw uint64 (never 0 or 1)."""
    return (float(x >> _U(11)) + 0.5) * _TWO53


@numba.njit(cache=True)
def fill_normals(out, seed, members, k0, stream, clip):  # type: ignore[no-untyped-def]
    """``out[s, q, i]``: normal ``i`` of step ``k0 + 1 + s`` of member ``members[q]``.

    Member ``m`` draws from Philox4x64-10 with key ``(seed, m)``; normal ``i`` of step ``k`` is
    the quantile of the uniform from word ``i % 4`` of the block at counter
    ``(i // 4, k, stream, 0)``: a fixed number of raw draws per step, so every step's normals
    are the same however the steps are cut into calls. Members ``< 0`` (padding) get zeros.
    ``clip > 0`` clips the normals to ``[-clip, clip]``.
    """
    nsteps, nm, count = out.shape
    key0 = _U(seed)
    stream_u = _U(stream)
    zero = _U(0)
    for q in range(nm):
        m = members[q]
        if m < 0:
            for s in range(nsteps):
                for i in range(count):
                    out[s, q, i] = 0.0
            continue
        key1 = _U(m)
        for s in range(nsteps):
            k = _U(k0 + 1 + s)
            row = out[s, q]
            for b in range((count + 3) // 4):
                w0, w1, w2, w3 = philox_block(_U(b), k, stream_u, zero, key0, key1)
                i = 4 * b
                row[i] = normal_quantile(_uniform(w0))
                if i + 1 < count:
                    row[i + 1] = normal_quantile(_uniform(w1))
                if i + 2 < count:
                    row[i + 2] = normal_quantile(_uniform(w2))
                if i + 3 < count:
                    row[i + 3] = normal_quantile(_uniform(w3))
            if clip > 0.0:
                for i in range(count):
                    v = row[i]
                    if v > clip:
                        row[i] = clip
                    elif v < -clip:
                        row[i] = -clip
