"""The ``noise=`` and ``noise_seed=`` keywords of the models: their transport noise."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._errors import ParameterError
from ..noise import TransportNoise, check_seed

__all__ = ["amplitude", "transport_noise"]

Array = NDArray[Any]


def amplitude(value: Any, what: str) -> float:
    """A noise amplitude: a finite number ``>= 0``, else a one-line :class:`ParameterError`."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ParameterError(f"{what} must be a number >= 0, got {value!r}")
    if not (np.isfinite(value) and value >= 0):
        raise ParameterError(f"{what} must be a finite number >= 0, got {value!r}")
    return float(value)


def transport_noise(
    model: str, noise: Any, seed: Any, default_fields: Any, **site: Any
) -> TransportNoise | None:
    """The model's :class:`~isoflow.noise.TransportNoise`: ``None`` without noise; for a number
    ``sigma``, ``sigma * default_fields()`` (the model's fields of unit amplitude); an array
    is taken as the fields themselves. ``seed`` is required with noise."""
    if noise is None and not site:
        return None
    seed = check_seed(seed, f"{model}: noise_seed")
    if noise is None:
        return TransportNoise(seed=seed, **site)
    if isinstance(noise, (int, float, np.integer, np.floating)) and not isinstance(noise, bool):
        sigma = amplitude(noise, f"{model}: noise")
        fields: Array = sigma * np.asarray(default_fields())
    else:
        fields = np.asarray(noise)
        if fields.dtype.kind not in "iufc":
            raise ParameterError(
                f"{model}: noise must be an amplitude or an array of fields, got {noise!r}"
            )
    return TransportNoise(fields, seed=seed, **site)
