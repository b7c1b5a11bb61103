"""The process pool of every parallel command: the calling process works, helpers that start once
and stay (docs/performance.md, "Many cores", says why and measures it).

``lawn evaluate``, ``benchmark``, ``gap`` and ``zoo`` map independent tasks over ``workers``
processes: this one and ``workers - 1`` helpers of a persistent pool (:func:`pool_map`,
:func:`shared_pool`); ``lawn sweep``, ``figures`` and ``train --seeds`` stream rows from a
:func:`worker_pool`. Helpers are ``spawn`` workers by default (``LAWN_START_METHOD`` or
``start_method=`` picks another). A command starts its helpers before its own set-up
(:func:`start_helpers`) and ends them at once when it fails before its map (:func:`stop_helpers`);
a helper gets tasks only once it has started, in chunks (:func:`chunk_size`) that shrink as the work
runs out, while this process plays one task at a time. A helper that dies while it holds tasks fails
the map with :class:`HelperDied`. Every process runs BLAS, OpenMP and numba on one thread
(:func:`single_threaded`): the episodes are the parallelism, and a task gives the same numbers in
whichever process plays it.
"""

from __future__ import annotations

import atexit
import multiprocessing
import os
import threading
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from typing import Any

__all__ = ["worker_pool", "shared_pool", "start_helpers", "stop_helpers", "shutdown_shared_pool", "HelperDied",
           "pool_map", "single_threaded", "chunk_size", "resolve_start_method"]

@dataclass
class _Shared:
    """This process's persistent pool: the pool, its helper count, the process that made it, its start
    method, the futures of its helpers' starts and the working directory it was made in."""

    pool: ProcessPoolExecutor | None = None
    helpers: int = 0
    pid: int = 0
    method: str | None = None
    starts: list[Future[int]] = field(default_factory=list)
    cwd: str | None = None


_SHARED = _Shared()

#: The environment variable that picks the helpers' start method (default ``spawn``).
START_METHOD_VARIABLE = "LAWN_START_METHOD"


def resolve_start_method(method: str | None = None) -> str:
    """The helpers' start method: ``method``, else ``$LAWN_START_METHOD``, else ``spawn``; one of
    the platform's (:func:`multiprocessing.get_all_start_methods`)."""
    method = method or os.environ.get(START_METHOD_VARIABLE) or "spawn"
    allowed = multiprocessing.get_all_start_methods()
    if method not in allowed:
        source = "start_method" if method != os.environ.get(START_METHOD_VARIABLE) else f"${START_METHOD_VARIABLE}"
        raise ValueError(f"{source}={method!r}: not a start method of this platform; valid: {', '.join(allowed)}")
    return method


def single_threaded() -> None:
    """Limit BLAS, OpenMP and numba to one thread in this process: threadpoolctl for the native
    pools already loaded, the environment variables for those loaded later, and numba's configuration
    reloaded while its thread pool is not running (so that a later compilation, which reloads it
    again, finds nothing changed)."""
    for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[name] = "1"
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)
    import numba
    from numba.core import config
    from numba.np.ufunc import parallel

    if getattr(parallel, "_is_initialized", False):  # already launched (a fork of a process that ran a
        numba.set_num_threads(1)                      # parallel kernel): its size is fixed, use one
    else:
        os.environ["NUMBA_NUM_THREADS"] = "1"
        config.reload_config()


def _die_with_parent(parent_pid: int) -> None:
    """The worker gets SIGKILL when the process that made the pool dies (Linux ``PR_SET_PDEATHSIG``),
    so a killed ``lawn sweep``/``evaluate`` leaves no workers behind."""
    import ctypes
    import signal
    import sys

    if sys.platform.startswith("linux"):  # the process that forked this one: the parent, or under
        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL), 0, 0, 0)  # forkserver the server,
    if os.getppid() != parent_pid:  # which exits with the parent. Did the parent die before that took effect?
        try:
            os.kill(parent_pid, 0)
        except ProcessLookupError:
            os._exit(1)


#: What a helper says when the main script starts helpers at its top level (the map goes on here without it).
UNGUARDED_MAIN = ("a helper process could not start: spawned helpers import the main script again, and this one "
                  "starts helpers at its top level; put that code under `if __name__ == \"__main__\":` (Python's "
                  "multiprocessing guide), or pass workers=1")


def _refuse_while_bootstrapping() -> None:
    """In a spawned helper that is importing the main script (multiprocessing's bootstrapping), a call
    that would start helpers ends the helper with :data:`UNGUARDED_MAIN` in one line instead of the
    main script's whole work and a spawn traceback; the calling process plays the map without it."""
    if getattr(multiprocessing.current_process(), "_inheriting", False):
        raise SystemExit(f"lawn: {UNGUARDED_MAIN}")


def _init_worker(parent_pid: int) -> None:
    """Worker initializer: die with the parent, one thread per library, and the simulation and the
    policies imported (numba's compiled kernels loaded from its cache) before the first task."""
    _die_with_parent(parent_pid)
    single_threaded()
    import agents  # noqa: F401  (lawn_env and its compiled kernels with it)


def worker_pool(workers: int, start_method: str | None = None) -> ProcessPoolExecutor:
    """A new pool of ``workers`` worker processes (children of this process that die with it, one
    thread per library; :func:`resolve_start_method`); the caller shuts it down (``with worker_pool(n) as pool``)."""
    _refuse_while_bootstrapping()
    context = multiprocessing.get_context(resolve_start_method(start_method))
    return ProcessPoolExecutor(max_workers=workers, mp_context=context, initializer=_init_worker,
                               initargs=(os.getpid(),))


def _ready() -> int:
    return os.getpid()


def shared_pool(helpers: int, start_method: str | None = None) -> ProcessPoolExecutor:
    """This process's persistent pool of ``helpers`` helper processes: made on first use, reused by
    every later call with the same count, start method and working directory, replaced when one of
    them changes or the pool broke."""
    method = resolve_start_method(start_method)
    pool: ProcessPoolExecutor | None = _SHARED.pool
    if pool is not None and _SHARED.pid != os.getpid():  # a forked child: the parent's pool is not its own
        _forget()
        pool = None
    if pool is not None and (_SHARED.helpers != helpers or _SHARED.method != method
                             or _SHARED.cwd != os.getcwd() or getattr(pool, "_broken", False)):
        shutdown_shared_pool()  # a new working directory too: the helpers resolve the tasks' relative paths
        pool = None
    if pool is None:
        pool = worker_pool(helpers, method)
        _SHARED.pool, _SHARED.helpers, _SHARED.pid, _SHARED.method = pool, helpers, os.getpid(), method
        _SHARED.starts, _SHARED.cwd = [], os.getcwd()
    return pool


def start_helpers(workers: int, start_method: str | None = None) -> list[Future[int]]:
    """Start the ``workers - 1`` helpers of a later :func:`pool_map` now, in the background (each
    imports lawn and loads its kernels while this process goes on): a command calls it before its own
    set-up. Returns a future per helper start (its result: a process id, once a helper has started);
    nothing for ``workers <= 1`` or inside a worker. Started once per pool: a later call returns the
    same futures."""
    if workers <= 1 or multiprocessing.parent_process() is not None:
        return []
    pool = shared_pool(workers - 1, start_method)
    if not _SHARED.starts:  # spawn workers start on demand: a small task each
        _SHARED.starts = [pool.submit(_ready) for _ in range(workers - 1)]
    return list(_SHARED.starts)


def _forget() -> tuple[ProcessPoolExecutor | None, int]:
    """Drop the persistent pool from this process's record; returns it and the process that made it."""
    pool, owner = _SHARED.pool, _SHARED.pid
    _SHARED.pool, _SHARED.helpers, _SHARED.pid, _SHARED.method, _SHARED.starts = None, 0, 0, None, []
    return pool, owner


def stop_helpers() -> None:
    """End this process's helpers at once, whatever they are doing (a command that fails before its
    map does not wait for helpers still starting)."""
    pool, owner = _forget()
    if pool is None or owner != os.getpid():
        return
    for helper in list((getattr(pool, "_processes", None) or {}).values()):  # this pool's, no other child
        helper.kill()  # SIGKILL: a helper holds nothing to clean up, and none outlives it
    manager = getattr(pool, "_executor_manager_thread", None)
    pool.shutdown(wait=False, cancel_futures=True)
    if manager is not None:  # the pool's manager thread sees them die and reaps them: the one thread
        manager.join(timeout=10)  # that waits on them (two waiting threads race for the exit status)


def shutdown_shared_pool() -> None:
    """Stop the persistent pool's workers (at exit, or to start afresh)."""
    pool, owner = _forget()
    if pool is not None and owner == os.getpid():
        pool.shutdown(wait=True, cancel_futures=True)


atexit.register(shutdown_shared_pool)


def chunk_size(tasks: int, workers: int) -> int:
    """Tasks per helper message for ``tasks`` still to hand out: about eight chunks per worker, at
    most 4 (an interrupted command waits for the chunks in flight), down to one as the work runs out
    (the last chunks are short, so no process waits long for another's)."""
    return max(1, min(4, tasks // (8 * workers)))


def _run_chunk(fn: Callable[[Any], Any], chunk: list[Any]) -> list[Any]:
    return [fn(task) for task in chunk]


def pool_map(fn: Callable[[Any], Any], tasks: list[Any], workers: int, progress: bool, desc: str,
             start_method: str | None = None, weight: Callable[[Any], int] | None = None) -> list[Any]:
    """``[fn(t) for t in tasks]`` over ``workers`` processes: this one and ``workers - 1`` helpers of
    this process's persistent pool (:func:`shared_pool`), with a progress bar; results in task order
    whatever the scheduling. This process plays one task at a time while each helper holds at most
    two chunks, so it starts at once and no helper waits for it. ``fn`` must be picklable (a
    module-level function or a ``functools.partial`` of one). Serial for ``workers <= 1``, one task,
    or inside a worker. ``weight(task)``: what a task counts for on the bar (the episodes of a task that
    plays several; 1 each by default)."""
    from tqdm.auto import tqdm

    if workers > 1:
        _refuse_while_bootstrapping()
    weigh = weight if weight is not None else _one
    bar = tqdm(total=sum(weigh(t) for t in tasks), desc=desc, unit="ep", disable=None if progress else True,
               leave=False)
    try:
        if workers <= 1 or len(tasks) <= 1 or multiprocessing.parent_process() is not None:  # in a worker: serially
            out = []
            for task in tasks:
                out.append(fn(task))
                bar.update(weigh(task))
            return out
        return _HelperMap(fn, tasks, workers, bar, start_method, weigh).run()
    finally:
        bar.close()


def _one(task: Any) -> int:
    return 1


class HelperDied(RuntimeError):
    """A helper process ended while it held tasks (killed, out of memory, a crash in native code)."""


class _HelperMap:
    """One map of :func:`pool_map` over this process and its helpers. A helper gets tasks only once
    it has started (its start future is done), at most two chunks at a time; each chunk that comes
    back hands the next one out at once (from the pool's result thread), so no helper waits for this
    process's task. This process plays the remaining tasks from the end, one at a time, then waits
    only for the chunks the helpers hold: a short map, or one whose helpers are still starting, is
    played here alone."""

    def __init__(self, fn: Callable[[Any], Any], tasks: list[Any], workers: int, bar: Any, start_method: str | None,
                 weight: Callable[[Any], int]):
        self.fn, self.tasks, self.workers, self.bar, self.weight = fn, tasks, workers, bar, weight
        self.starts = start_helpers(workers, start_method)
        self.pool = _SHARED.pool
        self.lock = threading.RLock()  # a callback may run in the thread that holds it (a future already done)
        self.returned = threading.Condition(self.lock)
        self.pending = deque(range(len(tasks)))  # task indices not yet handed out, in order
        self.results: list[Any] = [None] * len(tasks)
        self.in_flight: dict[Future[list[Any]], list[int]] = {}
        self.failure: list[BaseException] = []

    @staticmethod
    def died(error: BaseException, chunk: list[int]) -> HelperDied:
        return HelperDied(f"a helper process ended while it held tasks {chunk[0]}..{chunk[-1]} of this map ({error}); "
                          "rerun with --workers 1 (workers=1) to play them in this process and see what fails")

    def hand_out(self) -> None:
        if self.pool is None:  # no helpers (workers <= 1, or inside a worker): every task plays here
            return
        with self.lock:
            ready = sum(1 for f in self.starts if f.done() and not f.cancelled() and f.exception() is None)
            while self.pending and not self.failure and len(self.in_flight) < 2 * ready:
                size = chunk_size(len(self.pending), self.workers)  # shrinking with the work left: short tails
                chunk = [self.pending.popleft() for _ in range(min(size, len(self.pending)))]
                try:
                    future = self.pool.submit(_run_chunk, self.fn, [self.tasks[i] for i in chunk])
                except BrokenProcessPool as exc:
                    self.failure.append(self.died(exc, chunk))
                    return
                self.in_flight[future] = chunk
                future.add_done_callback(self.finished)

    # in the pool's result thread (or this one, for a done future)
    def finished(self, future: Future[list[Any]]) -> None:
        with self.lock:
            chunk = self.in_flight.pop(future, None)
            if chunk is not None and not future.cancelled():
                error = future.exception()
                if error is None:
                    for i, row in zip(chunk, future.result(), strict=True):
                        self.results[i] = row
                    self.bar.update(sum(self.weight(self.tasks[i]) for i in chunk))
                    self.hand_out()
                else:
                    self.failure.append(self.died(error, chunk) if isinstance(error, BrokenProcessPool) else error)
            self.returned.notify_all()

    def run(self) -> list[Any]:
        from threadpoolctl import threadpool_limits

        for start in self.starts:  # a helper that becomes ready takes its first chunks at once
            start.add_done_callback(lambda _: self.hand_out())
        try:
            with threadpool_limits(1):  # this process's tasks on one thread, as the helpers'
                while (i := self.next_here()) is not None:
                    self.results[i] = self.fn(self.tasks[i])
                    self.bar.update(self.weight(self.tasks[i]))
            with self.lock:
                while self.in_flight and not self.failure:
                    self.returned.wait()
            if self.failure:
                raise self.failure[0]
            return self.results
        except BaseException as exc:
            with self.lock:  # nothing more is handed out; what a helper has not begun is dropped
                self.failure.append(exc)
                self.pending.clear()
                for future in list(self.in_flight):
                    future.cancel()
            raise

    def next_here(self) -> int | None:
        """The next task this process plays (from the end: the helpers' chunks stay in order), after
        handing out what the started helpers can take; None when nothing is left or a map failed."""
        with self.lock:
            self.hand_out()
            if self.failure or not self.pending:
                return None
            return self.pending.pop()
