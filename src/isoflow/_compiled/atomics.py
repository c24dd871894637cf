"""An atomic counter for compiled loops: units handed to numba threads as the threads come free.

numba's ``omp`` and ``workqueue`` threading layers split a ``prange`` statically (each thread
gets its share before it starts, whatever ``numba.parallel_chunksize`` says: measured by
``benchmarks/parallel_split.py``). A loop over units whose costs differ (members that take
more iterations, members frozen after a failure) or whose threads share a core with other
work then waits for the thread with the most left. :func:`take` lets each thread of a
``prange`` over the threads take the next unit from a shared counter instead.
"""

from __future__ import annotations

from typing import Any

from numba.core import cgutils, types
from numba.extending import intrinsic

__all__ = ["take"]


@intrinsic
def take(typingctx: Any, counter: Any) -> Any:
    """``counter[0]`` before adding one to it, atomically (``counter``: ``int64[:]``).

    Relaxed ordering: the counter orders nothing but itself; the units' data are written by
    one thread each and read after the parallel region, which synchronizes.
    """
    if not (isinstance(counter, types.Array) and counter.dtype == types.int64):
        return None

    def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
        arrty = signature.args[0]
        ary = context.make_array(arrty)(context, builder, args[0])
        zero = context.get_constant(types.intp, 0)
        ptr = cgutils.get_item_pointer(context, builder, arrty, ary, [zero])
        one = context.get_constant(types.int64, 1)
        return builder.atomic_rmw("add", ptr, one, "monotonic")

    return types.int64(counter), codegen
