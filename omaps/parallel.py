"""Work handed out as threads ask for it: the kernels' dynamic schedule.

numba's ``prange`` splits its iterations into one contiguous range per thread, whatever
``numba.parallel_chunksize`` asks for under the OpenMP threading layer (measured: a loop whose
first half costs ten times its second ran no faster on two threads than on one). The bakers
visit triangles in texture order (``bake.micromap.locality_order``), where cost follows the
texture (and the tracer rows of an image, whose cost follows the picture), so a static split
left one thread waiting for the other. A kernel instead runs one ``prange`` iteration per thread
(``numba.get_num_threads()``), and each takes the next work item from a shared counter
(``fetch_add``, an atomic add) until none is left: the items keep their order, a thread that is
slowed (by the image or by the machine) takes fewer, and no thread waits longer than one item.
(numba may fold a read of the counter after the loop to its initial value: only ``fetch_add``
reads it.)

Example::

    >>> import numba, numpy as np
    >>> from omaps.parallel import fetch_add
    >>> @numba.njit(parallel=True)
    ... def squares(n):
    ...     out = np.zeros(n, np.int64)
    ...     counter = np.zeros(1, np.int64)
    ...     for w in numba.prange(numba.get_num_threads()):
    ...         while True:
    ...             i = fetch_add(counter, 1)
    ...             if i >= n:
    ...                 break
    ...             out[i] = i * i
    ...     return out
    >>> squares(5).tolist()
    [0, 1, 4, 9, 16]
"""

from __future__ import annotations

from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

__all__ = ["fetch_add", "item_size", "ITEMS_PER_THREAD"]

ITEMS_PER_THREAD = 8  # work items per thread at least, where there are enough units of work


@njit(cache=True, inline="always")
def item_size(n, n_threads, most):
    """Units of work (triangles) per item: ``most``, or fewer when ``n`` units would then make
    fewer than ITEMS_PER_THREAD items per thread (at least one unit). A fine level's chunk of a
    few triangles, each one costly, is then several items per thread, not one item for one
    thread while the others wait."""
    k = ITEMS_PER_THREAD * max(n_threads, 1)
    return max(1, min(most, (n + k - 1) // k))


@intrinsic
def fetch_add(typingctx, counter, step):
    """``counter[0] += step`` as one atomic operation on an int64 array; returns the value
    before. Threads calling it on one array each get a different value."""
    if not (isinstance(counter, types.Array) and counter.dtype == types.int64 and isinstance(step, types.Integer)):
        return None
    sig = types.int64(counter, step)

    def codegen(context, builder, signature, args):
        arr_t, step_t = signature.args
        ary = context.make_array(arr_t)(context, builder, args[0])
        zero = context.get_constant(types.intp, 0)
        ptr = cgutils.get_item_pointer(context, builder, arr_t, ary, [zero])
        value = context.cast(builder, args[1], step_t, types.int64)
        return builder.atomic_rmw("add", ptr, value, "monotonic")

    return sig, codegen
