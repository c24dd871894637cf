"""Explicit types for the compiled loops: the driver is specialized on types, never on objects.

The stage functions and the kernel's field are passed to the driver as first-class function
values (numba ``FunctionType``), and the driver is compiled eagerly for the exact argument
types of a run (:func:`compiled_driver`). numba's on-disk cache keys an entry by its types, so
one compilation per machine serves every later process and every field of the same signature
(see :mod:`isoflow._kernel_fields` for why dispatcher arguments would not do).
"""

from __future__ import annotations

from typing import Any

import numba
import numpy as np
from numba import types

from .._kernel_fields import field_type
from . import driver

__all__ = ["StageTypes", "compiled_driver", "stage_types"]


class StageTypes:
    """The function types of a run's field, ``iterate`` and ``finish``, and their arguments.

    Parameters
    ----------
    f, fargs :
        The kernel's field and its arguments.
    sp : tuple
        The stage parameters.
    dtype :
        The state's dtype (``B`` has the same dtype on every compiled layout).
    """

    def __init__(self, f: Any, fargs: tuple[Any, ...], sp: tuple[Any, ...], dtype: Any) -> None:
        self.dt = numba.from_dtype(np.dtype(dtype))
        A1 = types.Array(self.dt, 1, "C")
        A2 = types.Array(self.dt, 2, "C")
        self.fargs = numba.typeof(fargs)
        self.sp = numba.typeof(sp)
        self.f = field_type(f, fargs, dtype, dtype)
        f8 = types.float64
        self.iterate = types.FunctionType(
            f8(self.f, self.fargs, self.sp, A1, A1, A1, A1, A2, f8, f8)
        )
        self.finish = types.FunctionType(
            types.boolean(self.f, self.fargs, self.sp, A1, A1, A1, A2, types.float64, A1)
        )

    def compile_stage(self, iterate: Any, finish: Any) -> None:
        """Compile the stage functions for these types (loaded from the cache when there)."""
        iterate.compile(self.iterate.signature)
        finish.compile(self.finish.signature)

    def driver_signature(self) -> Any:
        """The signature of :func:`~isoflow._compiled.driver.drive_serial` for this run."""
        dt = self.dt
        i8, f8 = types.int64, types.float64
        return types.none(
            self.iterate, self.finish, self.f, self.fargs, self.sp, i8,
            types.Array(dt, 2, "C"), types.Array(dt, 4, "C"),
            types.Array(i8, 2, "C"), types.Array(i8, 2, "C"),
            types.Array(f8, 2, "C"), i8, types.Array(f8, 1, "C"),
            f8, i8, i8, i8, i8, types.Array(dt, 3, "C"),
            f8, f8, f8, f8, i8, i8, f8, types.Array(f8, 2, "C"),
        )  # fmt: skip


def stage_types(f: Any, fargs: tuple[Any, ...], sp: tuple[Any, ...], dtype: Any) -> StageTypes:
    """:class:`StageTypes` of a run."""
    return StageTypes(f, fargs, sp, dtype)


_DRIVERS: dict[Any, Any] = {}


def compiled_driver(signature: Any, parallel: bool) -> Any:
    """The driver compiled for ``signature`` (serial, or members over numba threads)."""
    key = (signature, parallel)
    d = _DRIVERS.get(key)
    if d is None:
        py = driver.drive_parallel if parallel else driver.drive_serial
        d = _DRIVERS[key] = numba.njit(signature, cache=True, parallel=parallel, nogil=True)(py)
    return d
