r"""Weights of the extrapolated start: a polynomial fitted to the last stage offsets.

IsoMP starts its solve from :math:`X^{(0)}_k = W_k + \sum_{q=1}^{m} c_q D_{k-q}`, the value
at step ``k`` of a polynomial in the step index fitted to the last ``m`` stage offsets
:math:`D_j = G(X_j) - W_j`. Two fits:

* **interpolation** (``m = p + 1`` offsets, degree ``p``): :math:`c_q = (-1)^{q+1}
  \binom{m}{q}`, an :math:`O(h^{p+1})` truncation error. It multiplies independent errors of
  size :math:`\varepsilon` in the offsets (their rounding, the accepted stage's residual) by
  :math:`\|c\|_2 = (\binom{2m}{m} - 1)^{1/2}`: 15.8 at ``p = 4``, 58.6 at ``p = 6``.
* **least squares** (``m > p + 1`` offsets, degree ``p``): the same order of truncation
  error with a larger constant, and a smaller gain on the offsets' errors (13.3 for
  ``p = 8`` on 16 offsets). It wins where the step is short against the state's motion, so
  that the offsets' rounding, not the truncation, limits the start: Euler on the sphere at
  ``N = 512``, ``h ||B||_2 = 0.3``, where the interpolating start of degree 6 leaves
  :math:`7 \cdot 10^{-14} \|W\|` (three quarters of it in the highest modes) and the solve
  needs three iterations a step, the least-squares start of degree 8 on 16 offsets
  :math:`1.3 \cdot 10^{-14} \|W\|` and two (``docs/user_guide/solvers.rst``).

The weights are exact rationals (Gaussian elimination on the normal equations in
``fractions.Fraction``) rounded once, so every process computes the same bits: a resumed
run continues with the start it began with.
"""

from __future__ import annotations

import math
from fractions import Fraction
from functools import cache

__all__ = ["interpolation_weights", "least_squares_weights", "start_weights"]


def interpolation_weights(m: int) -> tuple[float, ...]:
    """``c_q = (-1)^(q+1) binom(m, q)``, ``q = 1..m``: the value at the next step of the
    polynomial of degree ``m - 1`` through ``m`` offsets (newest first)."""
    return tuple(float((-1) ** (q + 1) * math.comb(m, q)) for q in range(1, m + 1))


@cache
def least_squares_weights(p: int, m: int) -> tuple[float, ...]:
    r"""``c_q``, ``q = 1..m``: the value at step ``k`` of the least-squares polynomial of
    degree ``p`` through the offsets at steps ``k - 1, ..., k - m`` (newest first).

    With :math:`V_{qj} = (-q)^j` (``q = 1..m``, ``j = 0..p``), the fit's value at ``0`` is
    :math:`c^T D` with :math:`c = V (V^T V)^{-1} e_0`, solved exactly.

    Parameters
    ----------
    p : int
        Degree, ``0 <= p < m``.
    m : int
        Offsets fitted.

    Returns
    -------
    tuple of float
        The weights, each the nearest float to its exact value; they sum to 1 (to rounding).

    Raises
    ------
    ValueError
        ``p`` not in ``[0, m)``.
    """
    if not 0 <= p < m:
        raise ValueError(f"least-squares start: degree {p} needs more than {p} offsets, got {m}")
    n = p + 1
    V = [[Fraction((-q) ** j) for j in range(n)] for q in range(1, m + 1)]
    # the normal equations (V^T V) z = e_0, augmented, by Gaussian elimination (exact: no pivoting
    # for size, only for a zero pivot, which the positive definite V^T V never has)
    zero = Fraction(0)
    A = [[sum((V[r][i] * V[r][j] for r in range(m)), zero) for j in range(n)] for i in range(n)]
    for i in range(n):
        A[i].append(Fraction(1 if i == 0 else 0))
    for c in range(n):
        for r in range(c + 1, n):
            f = A[r][c] / A[c][c]
            for j in range(c, n + 1):
                A[r][j] -= f * A[c][j]
    z = [zero] * n
    for i in reversed(range(n)):
        z[i] = (A[i][n] - sum((A[i][j] * z[j] for j in range(i + 1, n)), zero)) / A[i][i]
    return tuple(float(sum((V[q][j] * z[j] for j in range(n)), zero)) for q in range(m))


def start_weights(p: int | None, m: int) -> tuple[float, ...]:
    """The start's weights on ``m`` offsets for a fit of degree ``p``: interpolation through
    all of them while ``m <= p + 1`` (or ``p`` is ``None``), least squares of degree ``p``
    beyond.

    Parameters
    ----------
    p : int or None
        The fitted degree, or ``None`` for interpolation through every offset.
    m : int
        Offsets available (the first steps of a run have fewer than the method keeps).

    Returns
    -------
    tuple of float
        ``m`` weights, newest offset first.
    """
    if p is None or m <= p + 1:
        return interpolation_weights(m)
    return least_squares_weights(p, m)
