"""Explicit types for the compiled loops: the driver is specialized on types, never on objects.

The stage functions and the kernel's field are passed to the driver as first-class function
values (numba ``FunctionType``), and the driver is compiled eagerly for the exact argument
types of a run (:func:`compiled_driver`). numba's on-disk cache keys an entry by its types, so
one compilation per machine serves every later process and every field of the same signature
(see :mod:`isoflow._kernel_fields` for why dispatcher arguments would not do). The types of the
records, the layout record and the arrays are read off the values themselves
(``numba.typeof``), so nothing here restates the driver's parameter list.

Anderson mixing is passed the same way (``mix``: :func:`~isoflow._compiled.flat.anderson`, or
:func:`~isoflow._compiled.flat.no_mixing` for a run without it): a function the driver calls
directly is compiled into every driver again (numba links its code into the driver's and
optimizes the whole), and Anderson's took about 1 s of each driver's compilation and 4 s of
the first one's (measured, 2026-11-26), for the few runs that mix. The start is passed the same
way (``start``: :func:`~isoflow._compiled.flat.start`, or
:func:`~isoflow._compiled.dense_start.lower_start` on large dense states, whose threaded
pieces cost about 8 s of compilation that other runs should not pay).

A serial run of one unit (a single system, one member of :meth:`~isoflow._compiled.runner.
CompiledRunner._isolate`) calls :func:`~isoflow._compiled.driver.run_unit` itself
(:class:`OneUnit`): compiling the loop over units around it costs another 2-3 s of
optimization of the whole, for a loop of one.
"""

from __future__ import annotations

from typing import Any

import numba
import numpy as np
from numba import types

from .._kernel_fields import field_type
from . import driver

__all__ = ["DriverTypes", "OneUnit", "compiled_driver"]


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
        self.begin = types.FunctionType(types.none(*head, A1, A2, f8))
        self.iterate = types.FunctionType(types.none(*head, A1, A1, A1, A1, A2, f8, F1))
        self.finish = types.FunctionType(types.none(*head, A1, A1, A1, A2, f8, A1, A1, B1))
        F2 = types.Array(types.float64, 2, "C")
        I8 = types.int64
        self.mix = types.FunctionType(types.none(I8, A1, A1, A2, A2, F2, A1, A1, A1, F1, f8))
        self.start = types.FunctionType(
            types.boolean(numba.typeof(lay), A1, A2, I8, I8, F2, I8, f8, A1)
        )

    def compile_stage(self, begin: Any, iterate: Any, finish: Any, mix: Any, start: Any) -> None:
        """Compile the stage functions, the mixing and the start for these types (loaded from
        the cache when there)."""
        begin.compile(self.begin.signature)
        iterate.compile(self.iterate.signature)
        finish.compile(self.finish.signature)
        mix.compile(self.mix.signature)
        start.compile(self.start.signature)

    def driver_signature(self, args: tuple[Any, ...]) -> Any:
        """The signature of :func:`~isoflow._compiled.driver.drive_serial` for the call
        ``drive(begin, iterate, finish, mix, start, f, fargs, *args)``."""
        return types.none(
            self.begin, self.iterate, self.finish, self.mix, self.start, self.f, self.fargs,
            *(numba.typeof(a) for a in args),
        )  # fmt: skip


_DRIVERS: dict[Any, Any] = {}
_UNIT_LOOPS: dict[Any, Any] = {}


def compiled_driver(signature: Any, parallel: bool, units: int = 0) -> Any:
    """The driver compiled for ``signature`` (serial, or units over numba threads); a serial
    call of one unit (``units == 1``) gets :class:`OneUnit`, which calls the same way."""
    if units == 1 and not parallel:
        return OneUnit.of(signature)
    key = (signature, parallel)
    d = _DRIVERS.get(key)
    if d is None:
        py = driver.drive_parallel if parallel else driver.drive_serial
        d = _DRIVERS[key] = numba.njit(signature, cache=True, parallel=parallel, nogil=True)(py)
    return d


class OneUnit:
    """:func:`~isoflow._compiled.driver.drive_serial`'s call for arrays of one unit, made by
    calling :func:`~isoflow._compiled.driver.run_unit` on the unit's views (the same compiled
    step, without the loop over units to compile; see the module docstring).

    ``run_unit`` is compiled with the flags of its decorator (``nogil``): numba's on-disk
    cache does not key an entry by its flags, and the drivers' calls of ``run_unit`` share its
    entries.
    """

    def __init__(self, unit: Any) -> None:
        self.unit = unit

    @classmethod
    def of(cls, signature: Any) -> OneUnit:
        """The call for the driver signature ``signature`` (its arrays with the unit axis)."""
        d = _UNIT_LOOPS.get(signature)
        if d is None:
            head, per_unit, tail = _split(signature.args)
            one = tuple(a.copy(ndim=a.ndim - 1) for a in per_unit)
            sig = types.none(*head, *one, *tail, types.int64, types.int64)
            d = _UNIT_LOOPS[signature] = numba.njit(sig, cache=True, nogil=True)(
                driver.run_unit.py_func
            )
        return cls(d)

    def __call__(self, *args: Any) -> None:
        head, per_unit, tail = _split(args)
        self.unit(*head, *(a[0] for a in per_unit), *tail, 0, 0)  # member 0, thread 0


def _split(args: tuple[Any, ...]) -> tuple[tuple[Any, ...], tuple[Any, ...], tuple[Any, ...]]:
    """A driver's arguments (or their types) as ``(head, per_unit, tail)``: ``per_unit`` the
    arrays with a unit axis (``W, ring, head, nh, comp``), between the functions, the layout
    and the scratch count before them and the shared arrays, records and per-thread buffers
    after them."""
    return args[:10], args[10:15], args[15:]


@numba.njit(cache=True)
def no_begin(f, fargs, lay, mp, sd, W, work, h):  # type: ignore[no-untyped-def]
    """The explicit part of a stage that has none (never called: ``plan.begin`` is false)."""
