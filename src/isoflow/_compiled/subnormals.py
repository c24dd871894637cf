r"""Subnormal numbers flushed to zero inside the large dense products (x86-64).

The entries of a band-limited state far from its band are tiny and fall off fast: after a few
steps of Euler on the sphere from the ``euler-sphere`` random vorticity at ``N = 1024``, a
quarter of the entries are below ``1e-150``. A product of two of them is *subnormal*
(below ``2.2e-308``), and x86 processors compute subnormal results and operands in microcode,
about a hundred times slower than normal ones: one real product of the state's planes took
182 ms instead of 29 (measured, ``N = 1024``, one thread). Every product of the stage pays it
until the tails grow out of that range.

Inside the stage functions of the dense BLAS layouts the thread's floating-point control
register (MXCSR) gets the *flush-to-zero* and *denormals-are-zero* bits for the duration of the
call and is restored after it (:func:`flush_on`, :func:`flush_restore`; each numba thread of a
threaded pass sets its own). The arithmetic is otherwise IEEE: a result or operand below
``2.2e-308`` counts as zero, an absolute change of at most ``2.2e-308`` per operation, far
below the rounding of any entry that matters (``eps ||W||``), and the stage's structure, which
keeps the Casimirs, is unchanged. On other processors the two functions do nothing.

The caller's own setting is what :func:`flush_on` returns and :func:`flush_restore` puts back,
so code outside these functions (NumPy, the user's Python) never runs with the bits set.
"""

from __future__ import annotations

import platform

import numba
import numpy as np

__all__ = ["FLUSH_BITS", "control_word", "flush_on", "flush_restore", "flushes"]

#: MXCSR's flush-to-zero (bit 15) and denormals-are-zero (bit 6) bits.
FLUSH_BITS = 0x8040

#: Whether this machine has the control register (x86-64): elsewhere nothing is flushed.
flushes = platform.machine().lower() in ("x86_64", "amd64")

if flushes:
    import llvmlite.ir as ir
    from numba.core import cgutils, types
    from numba.extending import intrinsic

    def _mxcsr_call(builder, name, ptr):  # type: ignore[no-untyped-def]
        fnty = ir.FunctionType(ir.VoidType(), [ir.IntType(8).as_pointer()])
        fn = cgutils.get_or_insert_function(builder.module, fnty, f"llvm.x86.sse.{name}")
        builder.call(fn, [builder.bitcast(ptr, ir.IntType(8).as_pointer())])

    @intrinsic
    def _get_mxcsr(typingctx):  # type: ignore[no-untyped-def]
        def codegen(context, builder, signature, args):  # type: ignore[no-untyped-def]
            ptr = cgutils.alloca_once(builder, ir.IntType(32))
            _mxcsr_call(builder, "stmxcsr", ptr)
            return builder.load(ptr)

        return types.uint32(), codegen

    @intrinsic
    def _set_mxcsr(typingctx, value):  # type: ignore[no-untyped-def]
        def codegen(context, builder, signature, args):  # type: ignore[no-untyped-def]
            ptr = cgutils.alloca_once(builder, ir.IntType(32))
            builder.store(args[0], ptr)
            _mxcsr_call(builder, "ldmxcsr", ptr)
            return context.get_dummy_value()

        return types.void(types.uint32), codegen

    @numba.njit(cache=True, inline="always")
    def flush_on():  # type: ignore[no-untyped-def]
        """Set the calling thread's flush bits; return its previous control word."""
        old = _get_mxcsr()
        _set_mxcsr(old | np.uint32(FLUSH_BITS))
        return old

    @numba.njit(cache=True, inline="always")
    def flush_restore(old):  # type: ignore[no-untyped-def]
        """Put back the control word :func:`flush_on` returned."""
        _set_mxcsr(old)

    @numba.njit(cache=True)
    def control_word():  # type: ignore[no-untyped-def]
        """The calling thread's MXCSR (for tests)."""
        return _get_mxcsr()

else:  # pragma: no cover - other processors

    @numba.njit(cache=True, inline="always")
    def flush_on():  # type: ignore[no-untyped-def]
        """Nothing to set on this processor."""
        return np.uint32(0)

    @numba.njit(cache=True, inline="always")
    def flush_restore(old):  # type: ignore[no-untyped-def]
        """Nothing to restore on this processor."""

    @numba.njit(cache=True)
    def control_word():  # type: ignore[no-untyped-def]
        """No control word on this processor (0)."""
        return np.uint32(0)
