"""Random generators from the seeds users give (one check for every ``seed`` argument)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ._errors import ParameterError

__all__ = ["generator"]

_GENERATORS = (np.random.Generator, np.random.BitGenerator, np.random.SeedSequence)


def generator(seed: Any, what: str) -> np.random.Generator:
    """``numpy.random.default_rng(seed)`` for a valid ``seed``, else a one-line error.

    Parameters
    ----------
    seed : None, int >= 0, sequence of int >= 0, or a numpy Generator, BitGenerator or
        SeedSequence
        What :func:`numpy.random.default_rng` takes (a Generator is returned as it is, so
        passing one on gives the same numbers as passing its seed).
    what : str
        Names the argument in the message (``"euler_sphere: seed"``).

    Raises
    ------
    ParameterError
        A negative integer, a float, a string, a bool, ...
    """
    if seed is None or isinstance(seed, _GENERATORS):
        return np.random.default_rng(seed)
    values = np.asarray(seed) if isinstance(seed, list | tuple | np.ndarray) else None
    if values is not None and values.size and values.dtype.kind in "iu":
        if np.all(values >= 0):
            return np.random.default_rng(values)
    elif isinstance(seed, int | np.integer) and not isinstance(seed, bool | np.bool_):
        if seed >= 0:
            return np.random.default_rng(int(seed))
    raise ParameterError(
        f"{what} must be an integer >= 0 (or None, or a numpy Generator), got {seed!r}"
    )
