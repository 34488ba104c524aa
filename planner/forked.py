"""Run independent jobs in forked worker processes that inherit the jobs (no pickling of models on the way in).

Fork, not spawn: workers start at once and share the parent's read-only models (pinocchio, coal);
only the results travel back, pickled. Falls back to running inline where fork is unavailable.

Workers never outlive their parent: each asks the kernel for SIGKILL when the thread that forked
it dies (Linux `PR_SET_PDEATHSIG`, so even `kill -9` of the parent ends them), a pool left by an
exception (Ctrl-C, SIGTERM turned into `Terminated`) is killed rather than waited for (its workers are
forked together, those signals held until every one is in the pool's map), and
`stop_pools(thread)` kills the live pools a thread made (the workbench's background run, when it shuts down)
and refuses it any new one (`Stopped`): at exit CPython waits for every pool's jobs, so a pool started
after the kill, between two of a step's pools, kept a stopped workbench alive for minutes.
"""
from __future__ import annotations

import concurrent.futures
import contextlib
import ctypes
import multiprocessing
import os
import signal
import sys
import threading
import weakref
from collections.abc import Callable, Iterator, Sequence
from types import FrameType
from typing import Any

PR_SET_PDEATHSIG = 1  # from <linux/prctl.h>

_JOBS: tuple[Callable[[Any], Any], Sequence[Any]] | None = None
_LIVE: dict[concurrent.futures.ProcessPoolExecutor, threading.Thread] = {}  # live pools, by the thread that made them
_STOPPED: weakref.WeakSet[threading.Thread] = weakref.WeakSet()  # threads stop_pools was called for: no new pool
_LIVE_LOCK = threading.Lock()  # guards _LIVE and _STOPPED
_SPAWN_LOCK = threading.Lock()  # held while a pool forks its workers


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised in the main thread so that `finally` blocks run (pools killed, temporary files removed)."""


class Stopped(RuntimeError):
    """A thread whose pools `stop_pools` killed asked for a new one."""


def _raise_terminated(signum: int, frame: FrameType | None) -> None:
    raise Terminated()


@contextlib.contextmanager
def sigterm_unwinds() -> Iterator[None]:
    """Inside: SIGTERM unwinds the main thread like Ctrl-C (as `Terminated`) instead of ending the process on the spot."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGTERM, _raise_terminated)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _die_with_parent(parent: int) -> None:
    """In a forked worker: be killed when the parent goes (Linux), and go at once if it is already gone."""
    if sys.platform.startswith("linux"):
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0) != 0:
            raise OSError(ctypes.get_errno(), "prctl(PR_SET_PDEATHSIG) failed")
    if os.getppid() != parent:  # the parent died before the line above took effect
        os._exit(1)


def _child_init(parent: int, initializer: Callable[..., None] | None, initargs: tuple) -> None:
    # the parent's SIGTERM handler raises in the parent's code: a worker just ends on SIGTERM
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C goes to the whole group; the parent kills the pool
    _die_with_parent(parent)
    if initializer is not None:
        initializer(*initargs)


@contextlib.contextmanager
def _signals_deferred() -> Iterator[None]:
    """In the main thread: SIGTERM and SIGINT that arrive inside are handled on the way out, not in the middle.

    A worker forked but not yet entered in its pool's map would escape `_kill` (it died only later, by its
    parent-death signal, after the parent had already exited)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    arrived: list[int] = []
    previous = {s: signal.signal(s, lambda signum, frame: arrived.append(signum)) for s in (signal.SIGTERM, signal.SIGINT)}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        for s in dict.fromkeys(arrived):
            handler = previous[s]
            if callable(handler):
                handler(s, None)
            elif handler == signal.SIG_DFL:
                signal.raise_signal(s)


def _kill(pool: concurrent.futures.ProcessPoolExecutor) -> None:
    """Kill a pool's workers (not wait for their jobs) and release it."""
    with _SPAWN_LOCK:  # a pool forking in another thread has entered all its workers in its map first
        processes = list((getattr(pool, "_processes", None) or {}).values())  # CPython's map of the pool's workers
    for p in processes:
        with contextlib.suppress(OSError, ValueError):
            p.kill()
    manager = getattr(pool, "_executor_manager_thread", None)
    pool.shutdown(wait=False, cancel_futures=True)
    for p in processes:
        with contextlib.suppress(OSError, ValueError, AssertionError):
            p.join()
    if manager is not None:  # it closes its wake-up pipe as it ends; at exit, CPython writes to the pipes of those still
        manager.join()  # running without a lock ("Bad file descriptor" after a SIGTERM in CI)


def stop_pools(thread: threading.Thread) -> None:
    """Kill the workers of the pools `thread` made that are still running, and refuse it new ones (on shutdown, from
    another thread)."""
    with _LIVE_LOCK:
        _STOPPED.add(thread)
        pools = [pool for pool, owner in _LIVE.items() if owner is thread]
    for pool in pools:
        _kill(pool)


@contextlib.contextmanager
def worker_pool(workers: int, initializer: Callable[..., None] | None = None, initargs: tuple = ()
                ) -> Iterator[concurrent.futures.ProcessPoolExecutor]:
    """A pool of `workers` forked processes that die with their parent; on an exception its workers are killed, not awaited;
    `Stopped` in a thread `stop_pools` was called for."""
    pool = concurrent.futures.ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("fork"), initializer=_child_init,
                                                  initargs=(os.getpid(), initializer, initargs))
    with _LIVE_LOCK:
        if threading.current_thread() in _STOPPED:
            pool.shutdown(wait=False)  # no worker was forked yet: they start with the first job
            raise Stopped(f"thread '{threading.current_thread().name}' was stopped: it starts no more workers")
        _LIVE[pool] = threading.current_thread()
    try:
        with _SPAWN_LOCK, _signals_deferred():
            pool.submit(int)  # with fork, CPython forks every worker at the first job
        yield pool
        pool.shutdown(wait=True)
    except BaseException:
        _kill(pool)
        raise
    finally:
        with _LIVE_LOCK:
            _LIVE.pop(pool, None)


def _run(i: int) -> Any:
    assert _JOBS is not None
    fn, jobs = _JOBS
    return fn(jobs[i])


def forked_map(fn: Callable[[Any], Any], jobs: Sequence[Any], workers: int | None = None,
               on_result: Callable[[Any], None] | None = None) -> list[Any]:
    """[fn(job) for job in jobs], in order, over up to `workers` forked processes (default: the CPU count);
    `on_result` sees each result as it arrives, in order (for progress reports)."""
    global _JOBS
    workers = min(len(jobs), workers or os.cpu_count() or 1)
    if workers <= 1 or "fork" not in multiprocessing.get_all_start_methods():
        return _collect(map(fn, jobs), on_result)
    _JOBS = (fn, jobs)
    try:
        with worker_pool(workers) as pool:
            return _collect(pool.map(_run, range(len(jobs))), on_result)
    finally:
        _JOBS = None


def _collect(results: Iterator[Any], on_result: Callable[[Any], None] | None) -> list[Any]:
    out: list[Any] = []
    for result in results:
        out.append(result)
        if on_result is not None:
            on_result(result)
    return out
