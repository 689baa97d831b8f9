"""How tpvp's numba kernels are compiled and run on several threads, at the least compile cost.

:data:`JIT` holds the options of every kernel: cached on disk, and without the C-callable wrapper
numba otherwise builds for each kernel (for passing kernels to kernels as first-class functions,
which tpvp never does; ~5 % of a cold compile).

A worker kernel is compiled with ``nogil=True`` and takes ``(worker, workers)`` as its last two
arguments: it does items ``worker, worker + workers, ...`` (or the ``worker``-th of ``workers``
blocks) and writes only their outputs. :func:`run_workers` calls it once per worker on
``numba.get_num_threads()`` threads at most. This is what a ``prange`` over workers does, but a
``parallel=True`` kernel takes 1-7 s more to compile on a cold cache (its loop body goes through
numba's parfor passes); a serial kernel with ``nogil`` does not. Every item is computed by the same
code whichever worker takes it, so results do not depend on the number of threads.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numba

#: ``@njit(**JIT)``: cached on disk, no C-callable (first-class function) wrapper.
JIT = dict(cache=True, no_cfunc_wrapper=True)


def worker_count(items: int) -> int:
    """Workers for ``items`` items: numba's thread count (``NUMBA_NUM_THREADS``,
    ``numba.set_num_threads``), at most one per item, at least one."""
    return max(1, min(numba.get_num_threads(), int(items)))


def run_workers(kernel, items: int, *args) -> None:
    """``kernel(*args, worker, workers)`` for every worker, the first on the calling thread."""
    workers = worker_count(items)
    if workers == 1:
        kernel(*args, 0, 1)
        return
    with ThreadPoolExecutor(workers - 1) as pool:
        others = [pool.submit(kernel, *args, worker, workers) for worker in range(1, workers)]
        kernel(*args, 0, workers)
        for future in others:
            future.result()
