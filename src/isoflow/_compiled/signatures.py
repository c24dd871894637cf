"""Explicit types for the compiled loops: the driver is specialized on types, never on objects.

The stage functions and the kernel's field are passed to the driver as first-class function
values (numba ``FunctionType``), and the driver is compiled eagerly for the exact argument
types of a run (:func:`compiled_driver`). numba's on-disk cache keys an entry by its types, so
one compilation per machine serves every later process and every field of the same signature
(see :mod:`isoflow._kernel_fields` for why dispatcher arguments would not do). The types of the
records, the layout record and the arrays are read off the values themselves
(``numba.typeof``), so nothing here restates the driver's parameter list.
"""

from __future__ import annotations

from typing import Any

import numba
import numpy as np
from numba import types

from .._kernel_fields import field_type
from . import driver

__all__ = ["DriverTypes", "compiled_driver"]


class DriverTypes:
    """The function types of a run's field and stage, and the driver's signature.

    Parameters
    ----------
    f, fargs :
        The kernel's field and its arguments.
    lay, mp :
        The layout record and the method's parameters.
    dtype :
        The state's dtype (``B`` has the same dtype on every compiled layout).
    ndim :
        Axes of one state as the field sees it (``len(algebra.shape)``).
    """

    def __init__(self, f: Any, fargs: tuple[Any, ...], lay: Any, mp: tuple[Any, ...],
                 dtype: Any, ndim: int = 2) -> None:  # fmt: skip
        dt = numba.from_dtype(np.dtype(dtype))
        A1 = types.Array(dt, 1, "C")
        A2 = types.Array(dt, 2, "C")
        F1 = types.Array(types.float64, 1, "C")
        B1 = types.Array(types.boolean, 1, "C")
        SD = types.Array(types.float64, 2, "C")
        f8 = types.float64
        self.f = field_type(f, fargs, dtype, dtype, ndim)
        self.fargs = numba.typeof(fargs)
        head = (self.f, self.fargs, numba.typeof(lay), numba.typeof(mp), SD)
        self.begin = types.FunctionType(types.none(*head, A1, f8))
        self.iterate = types.FunctionType(types.none(*head, A1, A1, A1, A1, A2, f8, F1))
        self.finish = types.FunctionType(types.none(*head, A1, A1, A1, A2, f8, A1, B1))

    def compile_stage(self, begin: Any, iterate: Any, finish: Any) -> None:
        """Compile the stage functions for these types (loaded from the cache when there)."""
        begin.compile(self.begin.signature)
        iterate.compile(self.iterate.signature)
        finish.compile(self.finish.signature)

    def driver_signature(self, args: tuple[Any, ...]) -> Any:
        """The signature of :func:`~isoflow._compiled.driver.drive_serial` for the call
        ``drive(begin, iterate, finish, f, fargs, *args)``."""
        return types.none(
            self.begin, self.iterate, self.finish, self.f, self.fargs,
            *(numba.typeof(a) for a in args),
        )  # fmt: skip


_DRIVERS: dict[Any, Any] = {}


def compiled_driver(signature: Any, parallel: bool) -> Any:
    """The driver compiled for ``signature`` (serial, or units over numba threads)."""
    key = (signature, parallel)
    d = _DRIVERS.get(key)
    if d is None:
        py = driver.drive_parallel if parallel else driver.drive_serial
        d = _DRIVERS[key] = numba.njit(signature, cache=True, parallel=parallel, nogil=True)(py)
    return d


@numba.njit(cache=True)
def no_begin(f, fargs, lay, mp, sd, W, h):  # type: ignore[no-untyped-def]
    """The explicit part of a stage that has none (never called: ``plan.begin`` is false)."""
