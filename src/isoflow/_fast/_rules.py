"""The stopping rules of :mod:`isoflow.nonlinear`, compiled for the kernels.

The kernels call :data:`stopping_step`, a numba compilation (inlined) of the very function
the Python solvers use, so there is one statement of the rules.
"""

from __future__ import annotations

import numba

from ..nonlinear import (
    STATUS_CONVERGED,
    STATUS_DIVERGED,
    STATUS_MAX_ITER,
    STATUS_NON_FINITE,
    STATUS_RUNNING,
)
from ..nonlinear import stopping_step as _stopping_step

__all__ = [
    "STATUS_CONVERGED",
    "STATUS_DIVERGED",
    "STATUS_MAX_ITER",
    "STATUS_NON_FINITE",
    "STATUS_RUNNING",
    "stopping_step",
]

stopping_step = numba.njit(cache=True, inline="always")(_stopping_step)
