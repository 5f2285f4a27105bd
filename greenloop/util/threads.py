"""One mechanism for every parallel loop of greenloop's speed paths, and the one BLAS-thread limit.

* ``run_chunked`` / ``run_slices``: split a range over a few threads (BLAS calls, OpenCV and the
  numba kernels of ``greenloop.util.numba_kernels`` release the GIL), so no second thread pool
  (OpenBLAS's, numba's) spins on a core that another one needs (a multi-threaded OpenBLAS call next
  to a numba ``prange`` slows both down).
* ``one_blas_thread``: NumPy's BLAS on one thread, for the streaming detectors and the LSH timings.
"""
from __future__ import annotations

import contextlib
import functools
import os

import numpy as np

WORKERS = max(1, min(4, os.cpu_count() or 1))


@functools.lru_cache(maxsize=1)
def _pool():
    """Helper threads, made once per process (the calling thread takes a chunk too)."""
    from concurrent.futures import ThreadPoolExecutor
    return ThreadPoolExecutor(max(1, WORKERS - 1), thread_name_prefix="greenloop")


def split_rows(n: int) -> list[slice]:
    """range(n) cut into ``WORKERS`` (at most n) contiguous slices of nearly equal size."""
    edges = np.linspace(0, n, max(1, min(WORKERS, n)) + 1).round().astype(int)
    return [slice(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]


def run_slices(work, slices) -> None:
    """Call ``work(k, s)`` for the k-th slice s of ``slices``, in parallel threads (the caller
    takes the last). Exceptions propagate."""
    slices = list(slices)
    futures = [_pool().submit(work, k, s) for k, s in enumerate(slices[:-1])]
    if slices:
        work(len(slices) - 1, slices[-1])
    for f in futures:
        f.result()


def run_chunked(work, n: int, min_parallel: int = 8) -> None:
    """Call ``work(indices)`` on contiguous chunks of range(n) (numpy int arrays), one chunk per
    thread (``run_slices``); inline when n < min_parallel. Exceptions raised by ``work``
    propagate."""
    idx = np.arange(n)
    run_slices(lambda k, s: work(idx[s]), split_rows(n) if n >= min_parallel else [slice(None)])


@functools.lru_cache(maxsize=1)
def _blas_controller():
    try:
        from threadpoolctl import ThreadpoolController
        return ThreadpoolController().select(user_api="blas")
    except Exception:  # threadpoolctl absent or broken: keep BLAS as it is
        return None


def one_blas_thread():
    """A context manager that runs NumPy's BLAS on one thread (threadpoolctl), or a no-op when
    threadpoolctl is missing: the one BLAS limit of the streaming detectors and the LSH timings.

    On a shared 2-core machine a 2-thread OpenBLAS matmul waits at its barrier whenever one thread
    is preempted, which makes per-frame latencies long-tailed; one thread is also what one robot
    core would give. The BLAS libraries are looked up once per process.
    (cnn._fit_fused keeps its own ``threadpool_limits(limits=1)`` around training.)
    """
    blas = _blas_controller()
    return contextlib.nullcontext() if blas is None else blas.limit(limits=1)
