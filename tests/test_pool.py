"""The process pool (evaluation/pool.py): the calling process works beside its helpers, every process
on one thread per library, the helpers kept between maps, and parallel maps that work from an empty
kernel cache under every start method of the platform (numba compiles in the helpers)."""

import multiprocessing
import os
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from evaluation import pool

ROOT = Path(__file__).resolve().parent.parent


def _where(task):
    """The process and thread counts a task ran with (numba's configured count: asking for the
    running count would launch numba's thread pool)."""
    import time

    from numba.core import config
    from threadpoolctl import threadpool_info

    time.sleep(0.02)
    return task, os.getpid(), {info["num_threads"] for info in threadpool_info()}, config.NUMBA_NUM_THREADS


def _fail_on_three(task):
    if task == 3:
        raise ValueError(f"task {task} is bad")
    return task


def test_the_caller_and_one_helper_share_the_tasks_in_order_on_one_thread_each():
    pool.shutdown_shared_pool()
    for start in pool.start_helpers(2):  # started: it takes tasks from the first one on
        start.result(timeout=120)
    first = pool.pool_map(_where, list(range(24)), workers=2, progress=False, desc="")
    kept = pool.shared_pool(1)
    second = pool.pool_map(_where, list(range(24)), workers=2, progress=False, desc="")
    try:
        assert pool.shared_pool(1) is kept  # the helper stays for the next map
        assert [row[0] for row in first] == list(range(24)) == [row[0] for row in second]  # task order
        pids = {pid for _, pid, _, _ in first + second}
        assert os.getpid() in pids and len(pids) == 2  # this process and one helper
        assert all(threads == {1} for _, _, threads, _ in first + second)  # BLAS/OpenMP, here too during the map
        assert all(numba_threads == 1 for _, pid, _, numba_threads in first + second if pid != os.getpid())
    finally:
        pool.shutdown_shared_pool()


def test_a_failing_task_raises_in_the_caller_and_the_pool_serves_the_next_map():
    pool.shutdown_shared_pool()
    try:
        with pytest.raises(ValueError, match="task 3 is bad"):
            pool.pool_map(_fail_on_three, list(range(12)), workers=2, progress=False, desc="")
        assert pool.pool_map(_fail_on_three, [0, 1, 2, 4], workers=2, progress=False, desc="") == [0, 1, 2, 4]
    finally:
        pool.shutdown_shared_pool()


def test_an_unknown_start_method_is_named_with_the_platforms(monkeypatch):
    with pytest.raises(ValueError, match=r"start_method='threads'.*valid: .*spawn"):
        pool.worker_pool(2, start_method="threads")
    monkeypatch.setenv("LAWN_START_METHOD", "threads")
    with pytest.raises(ValueError, match=r"\$LAWN_START_METHOD='threads'.*valid: .*spawn"):
        pool.pool_map(_where, [0, 1], workers=2, progress=False, desc="")


def test_a_short_map_does_not_wait_for_helpers_still_starting():
    """Helpers get tasks only once started: a map shorter than a helper's start is played here."""
    pool.shutdown_shared_pool()
    try:
        rows = pool.pool_map(_where, [0, 1, 2], workers=3, progress=False, desc="")
        assert [row[0] for row in rows] == [0, 1, 2] and {row[1] for row in rows} == {os.getpid()}
    finally:
        pool.shutdown_shared_pool()


def _sleep(task):
    import time

    time.sleep(task)
    return os.getpid()


def test_a_helper_keeps_working_while_the_caller_plays_a_long_task():
    """Each chunk a helper returns hands it the next, whatever the caller is playing: with a long last
    task (the caller plays from the end) the helper plays every other one."""
    pool.shutdown_shared_pool()
    try:
        for start in pool.start_helpers(2):
            start.result(timeout=120)
        pids = pool.pool_map(_sleep, [0.02] * 30 + [3.0], workers=2, progress=False, desc="")
        assert pids[-1] == os.getpid() and os.getpid() not in pids[:-1]
    finally:
        pool.shutdown_shared_pool()


def _die_in_a_helper(task):
    import multiprocessing as mp

    if mp.parent_process() is not None:
        os._exit(3)
    return task


def test_a_helper_that_dies_fails_the_map_with_a_clear_error_and_the_next_map_works():
    pool.shutdown_shared_pool()
    try:
        for start in pool.start_helpers(2):
            start.result(timeout=120)
        with pytest.raises(pool.HelperDied, match=r"helper process ended while it held tasks .*--workers 1"):
            pool.pool_map(_die_in_a_helper, list(range(40)), workers=2, progress=False, desc="")
        rows = pool.pool_map(_where, list(range(8)), workers=2, progress=False, desc="")  # a fresh pool
        assert [row[0] for row in rows] == list(range(8))
    finally:
        pool.shutdown_shared_pool()


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads process states from /proc")
def test_stop_helpers_ends_them_at_once():
    import multiprocessing as mp

    pool.shutdown_shared_pool()
    before = set(mp.active_children())  # processes of other tests' pools in this worker are not ours
    starts = pool.start_helpers(3)
    helpers = [c for c in mp.active_children() if c not in before]
    assert len(starts) == 2 and len(helpers) == 2
    pool.stop_helpers()
    deadline = time.monotonic() + 10
    while any(_running(child.pid) for child in helpers) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not [child.pid for child in helpers if _running(child.pid)]


def _running(pid: int) -> bool:
    """Whether process ``pid`` still runs: neither reaped nor a zombie. (``Process.is_alive`` can read
    True for a child the pool's manager thread reaped first: its own ``waitpid`` then finds no child.)"""
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


_KERNEL_MODULE = '''
import os

import numba
import numpy as np


@numba.njit(cache=True)
def _square_sum(x):
    total = 0.0
    for v in x:
        total += v * v
    return total


def task(n):
    """Compiles on first call in each process: the cache directory starts empty."""
    import time

    time.sleep(0.05)
    return os.getpid(), _square_sum(np.arange(float(n)))
'''


@pytest.mark.parametrize("method", multiprocessing.get_all_start_methods())
def test_parallel_map_compiles_in_the_helpers_from_an_empty_kernel_cache(tmp_path, method):
    """The main job's failure on a fresh machine: a helper that set numba's thread count and then
    compiled a kernel raised "Cannot set NUMBA_NUM_THREADS to a different value once the threads
    have been launched"."""
    (tmp_path / "coldtask.py").write_text(_KERNEL_MODULE)
    # a main module that imports numba at the top, as the lawn command does: spawn and forkserver
    # helpers import it again before their initializer runs
    (tmp_path / "main.py").write_text(textwrap.dedent(f"""
        import coldtask
        from evaluation.pool import pool_map, start_helpers

        if __name__ == "__main__":
            for start in start_helpers(2, {method!r}):  # the helper has started: it plays tasks too
                start.result(timeout=120)
            rows = pool_map(coldtask.task, list(range(1, 13)), workers=2, progress=False, desc="",
                            start_method={method!r})
            print(len({{pid for pid, _ in rows}}), [value for _, value in rows])
    """))
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"), PYTHONPATH=f"{tmp_path}{os.pathsep}{ROOT}")
    env.pop("NUMBA_NUM_THREADS", None)
    done = subprocess.run([sys.executable, "main.py"], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=240)
    assert done.returncode == 0, done.stderr[-3000:]
    processes, values = done.stdout.split(" ", 1)
    assert values.strip() == str([float(sum(i * i for i in range(n))) for n in range(1, 13)])
    assert processes == "2"  # the caller and its helper both compiled and played
    assert any((tmp_path / "cache").rglob("*.nbi"))


def test_a_script_without_the_main_guard_gets_one_line_not_a_spawn_traceback(tmp_path):
    """A plain script that calls compare(workers=2) at its top level: each spawned helper imports the
    script again; it ends at once with one line saying what to do, and the script's own process plays
    the comparison (the same results as workers=1) instead of a traceback per helper."""
    script = tmp_path / "unguarded.py"
    script.write_text("from evaluation.api import compare\n"
                      "result = compare(['epa', 'pid'], config={'num_slots': 5}, seeds=range(4), workers=2)\n"
                      "print(result.costs('pid'))\n")
    done = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True, timeout=300,
                          check=False)
    assert done.returncode == 0, done.stderr
    from evaluation.api import compare

    assert done.stdout.strip() == str(compare(["epa", "pid"], {"num_slots": 5}, range(4)).costs("pid"))
    assert "Traceback" not in done.stderr, done.stderr
    lines = [line for line in done.stderr.splitlines() if line.strip()]
    assert lines and all(line == f"lawn: {pool.UNGUARDED_MAIN}" for line in lines), done.stderr
    assert 'if __name__ == "__main__":' in pool.UNGUARDED_MAIN


def test_the_persistent_pool_follows_the_working_directory(tmp_path, monkeypatch):
    """Helpers resolve a task's relative paths (sb3:runs/..., --out) in their own working directory:
    after a chdir the persistent pool is replaced, so they resolve them where the caller does."""
    first = pool.shared_pool(1)
    try:
        assert pool.shared_pool(1) is first
        monkeypatch.chdir(tmp_path)
        second = pool.shared_pool(1)
        assert second is not first
        assert second.submit(os.getcwd).result(timeout=240) == str(tmp_path)
    finally:
        pool.shutdown_shared_pool()
