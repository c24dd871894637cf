r"""Spins at finite temperature: stochastic Landau–Lifshitz–Gilbert in isospectral form.

.. math::

    dS_i = -S_i \times \big(H_i\,dt + \sqrt{2D} \circ d\beta_i\big)
           - \lambda\, S_i \times (S_i \times H_i)\,dt, \qquad H_i = -\nabla_i E,

is :math:`dS = [B(S), S]\,dt + \sum [B_j, S] \circ d\beta_j` on :math:`(\mathbb{R}^3,\times)^N`
(:math:`[B, S] = B \times S`) with

.. math::

    B_i(S) = H_i + \lambda\, S_i \times H_i, \qquad
    \text{site noise of amplitude } \sqrt{2D} \text{ on every spin},

since :math:`(\lambda S \times H) \times S = -\lambda S \times (S \times H)`: the Gilbert
damping is the double bracket :math:`\alpha [[P, W], W]` of :math:`B = P + \alpha [P, W]` with
:math:`P = H` and :math:`\alpha = -\lambda` (here :math:`[P, W] = H \times S`). The midpoint
keeps every :math:`|S_i|` for every path. Fluctuation–dissipation: the Gibbs density
:math:`e^{-E/k_B T}` on the spheres is stationary exactly when :math:`D = \lambda k_B T`
(``docs/theory/stochastic.rst``; :math:`k_B = 1`).
"""

from __future__ import annotations

from typing import Any

import numba
import numpy as np

from .._errors import ParameterError
from ..noise import TransportNoise, check_seed
from ._noise import amplitude

__all__ = ["gilbert", "thermal_noise"]


@numba.njit(cache=True, inline="always")
def gilbert(W, out, lam):  # type: ignore[no-untyped-def]
    r"""``out_i = H_i + lam S_i x H_i`` in place (``out`` holds ``H``), ``(N, 3)``."""
    for i in range(W.shape[0]):
        s0, s1, s2 = W[i, 0], W[i, 1], W[i, 2]
        h0, h1, h2 = out[i, 0], out[i, 1], out[i, 2]
        out[i, 0] = h0 + lam * (s1 * h2 - s2 * h1)
        out[i, 1] = h1 + lam * (s2 * h0 - s0 * h2)
        out[i, 2] = h2 + lam * (s0 * h1 - s1 * h0)


def thermal_noise(
    model: str, temperature: Any, damping: Any, noise_seed: Any
) -> tuple[float, float, TransportNoise | None]:
    r"""``(T, lambda, noise)`` of a spin model: the site noise :math:`\sqrt{2\lambda T}` when
    ``T > 0`` (``noise_seed`` required).

    Raises
    ------
    ParameterError
        A negative or non-finite temperature or damping, ``temperature > 0`` without damping
        (no noise would balance it: :math:`D = \lambda T`), a missing seed.
    """
    T = amplitude(temperature, f"{model}: temperature")
    lam = amplitude(damping, f"{model}: damping")
    if T == 0.0:
        return T, lam, None
    if lam == 0.0:
        raise ParameterError(
            f"{model}: temperature = {T:g} needs damping > 0 (the noise strength is "
            "D = damping * temperature)"
        )
    seed = check_seed(noise_seed, f"{model}: noise_seed")
    return T, lam, TransportNoise(site=float(np.sqrt(2.0 * lam * T)), seed=seed)
