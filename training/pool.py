"""The process pool of every parallel command: workers that start once and stay.

Each ``lawn`` command that plays episodes in parallel (``evaluate``, ``benchmark``, the suite,
``gap``, ``figures``, ``zoo``) maps independent tasks over ``spawn`` workers (fresh interpreters,
safe with torch and OpenMP thread pools). Starting one costs an interpreter, the imports and the
loading of numba's cache, about a second; the suite alone maps six batches. So
:func:`pool_map` keeps one pool per process (:func:`shared_pool`) and reuses it for every batch
with the same worker count; it is shut down when the process exits.

Inside a worker every numerical library runs on one thread (:func:`single_threaded`): the
episodes are the parallelism. An OpenBLAS or OpenMP pool per worker would start as many threads as
the machine has cores, and N workers would share the cores with N times that many threads.

Tasks go to the workers in chunks (``chunksize``): one message per chunk instead of per episode,
so the parent's share of the work does not grow with the number of workers
(``benchmarks/parallel_scaling.py`` measures it).
"""

from __future__ import annotations

import atexit
import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any, Callable

from tqdm.auto import tqdm

__all__ = ["worker_pool", "shared_pool", "shutdown_shared_pool", "pool_map", "single_threaded", "chunk_size"]

_SHARED: dict[str, Any] = {"pool": None, "workers": 0, "pid": 0}


def single_threaded() -> None:
    """Limit BLAS, OpenMP and numba to one thread in this process (threadpoolctl for the native
    pools that are already loaded; the environment variables for those loaded later)."""
    for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
        os.environ[name] = "1"
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)
    import numba

    numba.set_num_threads(1)


def _die_with_parent(parent_pid: int) -> None:
    """The worker gets SIGKILL when the process that made the pool dies (Linux ``PR_SET_PDEATHSIG``),
    so a killed ``lawn sweep``/``evaluate`` leaves no workers behind."""
    import ctypes
    import signal
    import sys

    if sys.platform.startswith("linux"):
        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL), 0, 0, 0)  # PR_SET_PDEATHSIG
    if os.getppid() != parent_pid:  # the parent died before the line above took effect
        os._exit(1)


def _init_worker(parent_pid: int) -> None:
    """Worker initializer: die with the parent, one thread per library, and the simulation and the
    policies imported (numba's compiled kernels loaded from its cache) before the first task."""
    _die_with_parent(parent_pid)
    single_threaded()
    import agents  # noqa: F401  (lawn_env and its compiled kernels with it)


def worker_pool(workers: int) -> ProcessPoolExecutor:
    """A new pool of ``workers`` ``spawn`` workers (children of this process that die with it, one
    thread per library); the caller shuts it down (``with worker_pool(n) as pool``)."""
    return ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                               initializer=_init_worker, initargs=(os.getpid(),))


def shared_pool(workers: int) -> ProcessPoolExecutor:
    """This process's persistent pool of ``workers`` workers: made on first use, reused by every
    later call with the same count, replaced when the count changes or the pool broke."""
    pool = _SHARED["pool"]
    if pool is not None and _SHARED["pid"] != os.getpid():  # a forked child: the parent's pool is not its own
        _SHARED.update(pool=None, workers=0, pid=0)
        pool = None
    if pool is not None and (_SHARED["workers"] != workers or getattr(pool, "_broken", False)):
        shutdown_shared_pool()
        pool = None
    if pool is None:
        pool = worker_pool(workers)
        _SHARED.update(pool=pool, workers=workers, pid=os.getpid())
    return pool


def shutdown_shared_pool() -> None:
    """Stop the persistent pool's workers (at exit, or to start afresh)."""
    pool, owner = _SHARED["pool"], _SHARED["pid"]
    _SHARED.update(pool=None, workers=0, pid=0)
    if pool is not None and owner == os.getpid():
        pool.shutdown(wait=True, cancel_futures=True)


atexit.register(shutdown_shared_pool)


def chunk_size(tasks: int, workers: int) -> int:
    """Tasks per message: about eight chunks per worker (short tails, balanced loads), at most 4 (an
    interrupted command waits for the chunks in flight)."""
    return max(1, min(4, tasks // (8 * workers)))


def _run_chunk(fn: Callable[[Any], Any], chunk: list) -> list:
    return [fn(task) for task in chunk]


def pool_map(fn: Callable[[Any], Any], tasks: list, workers: int, progress: bool, desc: str) -> list:
    """``[fn(t) for t in tasks]`` in this process's persistent pool (:func:`shared_pool`) when
    ``workers > 1``, in chunks, with a progress bar; results in task order whatever the scheduling.
    ``fn`` must be picklable (a module-level function or a ``functools.partial`` of one)."""
    bar = tqdm(total=len(tasks), desc=desc, unit="ep", disable=None if progress else True, leave=False)
    try:
        if workers <= 1 or len(tasks) <= 1 or multiprocessing.parent_process() is not None:  # in a worker: serially
            out = []
            for task in tasks:
                out.append(fn(task))
                bar.update()
            return out
        size = chunk_size(len(tasks), workers)
        chunks = [tasks[i:i + size] for i in range(0, len(tasks), size)]
        pool = shared_pool(workers)
        try:
            futures = [pool.submit(_run_chunk, fn, chunk) for chunk in chunks]
        except BrokenProcessPool:  # a worker died since the last batch: start afresh once
            shutdown_shared_pool()
            pool = shared_pool(workers)
            futures = [pool.submit(_run_chunk, fn, chunk) for chunk in chunks]
        for fut, chunk in zip(futures, chunks):
            fut.add_done_callback(lambda _, n=len(chunk): bar.update(n))
        try:
            return [row for fut in futures for row in fut.result()]
        except BaseException:
            for fut in futures:
                fut.cancel()
            raise
    finally:
        bar.close()
