"""The stopping rules of :mod:`isoflow.nonlinear`, compiled for the compiled loops.

:data:`stopping_step` is a numba compilation (inlined) of the very function the Python
solvers call, so the rules are stated once.
"""

from __future__ import annotations

import numba

from ..nonlinear import (
    ANDERSON_REGULARIZATION,
    CONTINUE,
    STATUS_CONVERGED,
    STATUS_DIVERGED,
    STATUS_MAX_ITER,
    STATUS_NON_FINITE,
)
from ..nonlinear import stopping_step as _stopping_step

__all__ = [
    "ANDERSON_REGULARIZATION",
    "CONTINUE",
    "STATUS_CONVERGED",
    "STATUS_DIVERGED",
    "STATUS_MAX_ITER",
    "STATUS_NON_FINITE",
    "stopping_step",
]

stopping_step = numba.njit(cache=True, inline="always")(_stopping_step)
