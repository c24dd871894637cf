"""The check of a flag argument: a bool, not anything truthy (``force="no"`` would count as
true and replace a file)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ._errors import ParameterError

__all__ = ["check_flag"]


def check_flag(value: Any, name: str) -> None:
    """``value`` is a bool (Python's or numpy's), else a :class:`~isoflow.ParameterError`
    naming ``name``."""
    if not isinstance(value, (bool, np.bool_)):
        raise ParameterError(f"{name} must be True or False, got {value!r}")
