"""Run independent jobs in forked worker processes that inherit the jobs (no pickling of models on the way in).

Fork, not spawn: workers start at once and share the parent's read-only models (pinocchio's and the collision shapes);
only the results travel back, pickled. Falls back to running inline where fork is unavailable.

Workers never outlive their parent: each asks the kernel for SIGKILL when the thread that forked
it dies (Linux `PR_SET_PDEATHSIG`, so even `kill -9` of the parent ends them), a pool left by an
exception (Ctrl-C, SIGTERM turned into `Terminated`) is killed rather than waited for (its workers are
forked together, those signals held until every one is recorded as the pool's), and
`stop_pools(thread)` kills the live pools a thread made (the workbench's background run, when it shuts down)
and refuses it any new one (`Stopped`): at exit CPython waits for every pool's jobs, so a pool started
after the kill, between two of a step's pools, kept a stopped workbench alive for minutes.

Pools nest: a job on a worker may make a pool of its own. A forked child re-creates the module's locks and tables
(`os.register_at_fork`), so it never waits on a lock its parent held while forking it, and the jobs of `forked_map`
reach its workers through their initializer, not a table of the parent's. How many processes a pool may fork is bounded
by `cpu_budget` (a suite's executor gives each task the CPUs it was given): `available_cpus()`.
"""
from __future__ import annotations

import concurrent.futures
import contextlib
import ctypes
import dataclasses
import multiprocessing
import os
import signal
import sys
import threading
import weakref
from collections.abc import Callable, Iterator, Sequence
from types import FrameType
from typing import Any

import threadpoolctl

PR_SET_PDEATHSIG = 1  # from <linux/prctl.h>

_JOBS: tuple[Callable[[Any], Any], Sequence[Any]] | None = None  # in a forked_map worker only: its jobs (set by its initializer)
_BUDGET: int | None = None  # CPUs this process may use (cpu_budget); None: every CPU it is allowed to run on


@dataclasses.dataclass
class _Live:
    """A live pool's thread, its worker processes (recorded once forked, under _SPAWN_LOCK) and the lock its shutdowns
    take: CPython's `shutdown(wait=True)` run in two threads at once closes the pool's result queue twice."""

    owner: threading.Thread
    workers: list[multiprocessing.process.BaseProcess] = dataclasses.field(default_factory=list)
    closing: threading.Lock = dataclasses.field(default_factory=threading.Lock)


_LIVE: dict[concurrent.futures.ProcessPoolExecutor, _Live] = {}  # live pools
_STOPPED: weakref.WeakSet[threading.Thread] = weakref.WeakSet()  # threads stop_pools was called for: no new pool
_LIVE_LOCK = threading.Lock()  # guards _LIVE and _STOPPED
_SPAWN_LOCK = threading.Lock()  # held while a pool forks its workers


def _reset_in_child() -> None:
    """In a freshly forked child: new locks (the parent may have held one while forking) and no pools of the parent's."""
    global _LIVE_LOCK, _SPAWN_LOCK, _LIVE, _STOPPED
    _LIVE_LOCK, _SPAWN_LOCK = threading.Lock(), threading.Lock()
    _LIVE, _STOPPED = {}, weakref.WeakSet()


os.register_at_fork(after_in_child=_reset_in_child)


def available_cpus() -> int:
    """How many processes this process's pools may run at once: its `cpu_budget`, else the CPUs it may run on."""
    return _BUDGET or max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1)


@contextlib.contextmanager
def cpu_budget(cpus: int) -> Iterator[None]:
    """Inside: this process's pools use at most `cpus` processes (one runs inline), so that a suite task stays on the
    CPUs its executor gave it."""
    global _BUDGET
    previous, _BUDGET = _BUDGET, max(1, cpus)
    try:
        yield
    finally:
        _BUDGET = previous


class _Inline(concurrent.futures.Executor):
    """An executor that runs each job at once in this process (a pool of one CPU: no process to fork)."""

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> concurrent.futures.Future:
        future: concurrent.futures.Future = concurrent.futures.Future()
        try:
            future.set_result(fn(*args, **kwargs))
        except Exception as exc:
            future.set_exception(exc)
        return future


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
    # one BLAS thread per worker: the workers fill the cores already, and the threads the worker inherits from the
    # parent's BLAS spin against the other workers (the motion's smoothing ran five times slower without this)
    threadpoolctl.threadpool_limits(1)
    if initializer is not None:
        initializer(*initargs)


@contextlib.contextmanager
def _signals_deferred() -> Iterator[None]:
    """In the main thread: SIGTERM and SIGINT that arrive inside are handled on the way out, not in the middle.

    A worker forked but not yet recorded as its pool's would escape `_kill` (it died only later, by its
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


def _fork_workers(pool: concurrent.futures.ProcessPoolExecutor, into: list[multiprocessing.process.BaseProcess]) -> None:
    """Make `pool` fork its workers (with fork, CPython forks every one at the first job) and record them `into`: the
    children this process gained meanwhile (pools fork one at a time, under _SPAWN_LOCK)."""
    before = set(multiprocessing.active_children())
    try:
        pool.submit(int)
    finally:
        into.extend(p for p in multiprocessing.active_children() if p not in before)


def _kill(pool: concurrent.futures.ProcessPoolExecutor, live: _Live) -> None:
    """Kill a pool's workers (not wait for their jobs) and release it."""
    with _SPAWN_LOCK:  # a pool forking in another thread has recorded all its workers first
        workers = list(live.workers)
    for p in workers:
        with contextlib.suppress(OSError, ValueError):
            p.kill()
    # its manager thread sees the workers gone and ends; waited for, since it closes its wake-up pipe as it ends and at
    # exit CPython writes to the pipes of those still running without a lock ("Bad file descriptor" after a SIGTERM in CI)
    with live.closing:
        pool.shutdown(wait=True, cancel_futures=True)


def stop_pools(thread: threading.Thread) -> None:
    """Kill the workers of the pools `thread` made that are still running, and refuse it new ones (on shutdown, from
    another thread)."""
    with _LIVE_LOCK:
        _STOPPED.add(thread)
        pools = [(pool, live) for pool, live in _LIVE.items() if live.owner is thread]
    for pool, live in pools:
        _kill(pool, live)


@contextlib.contextmanager
def worker_pool(workers: int, initializer: Callable[..., None] | None = None, initargs: tuple = ()
                ) -> Iterator[concurrent.futures.ProcessPoolExecutor]:
    """A pool of `workers` forked processes that die with their parent; on an exception its workers are killed, not awaited;
    `Stopped` in a thread `stop_pools` was called for."""
    workers = max(1, min(workers, _BUDGET or workers))
    pool = concurrent.futures.ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("fork"), initializer=_child_init,
                                                  initargs=(os.getpid(), initializer, initargs))
    live = _Live(threading.current_thread())
    with _LIVE_LOCK:
        if threading.current_thread() in _STOPPED:
            pool.shutdown(wait=False)  # no worker was forked yet: they start with the first job
            raise Stopped(f"thread '{threading.current_thread().name}' was stopped: it starts no more workers")
        _LIVE[pool] = live
    try:
        with _SPAWN_LOCK, _signals_deferred():
            _fork_workers(pool, live.workers)
        yield pool
        with live.closing:
            pool.shutdown(wait=True)
    except BaseException:
        _kill(pool, live)
        raise
    finally:
        with _LIVE_LOCK:
            _LIVE.pop(pool, None)


@contextlib.contextmanager
def executor(workers: int, initializer: Callable[..., None] | None = None, initargs: tuple = ()
             ) -> Iterator[concurrent.futures.Executor]:
    """`worker_pool(workers, ...)`, or jobs run inline (after `initializer`) when only one CPU is to be used."""
    workers = min(workers, available_cpus())
    if workers > 1 and "fork" in multiprocessing.get_all_start_methods():
        with worker_pool(workers, initializer, initargs) as pool:
            yield pool
        return
    if initializer is not None:
        initializer(*initargs)
    yield _Inline()


def _set_jobs(fn: Callable[[Any], Any], jobs: Sequence[Any]) -> None:
    global _JOBS
    _JOBS = (fn, jobs)


def _run(i: int) -> Any:
    assert _JOBS is not None
    fn, jobs = _JOBS
    return fn(jobs[i])


def forked_map(fn: Callable[[Any], Any], jobs: Sequence[Any], workers: int | None = None,
               on_result: Callable[[Any], None] | None = None) -> list[Any]:
    """[fn(job) for job in jobs], in order, over up to `workers` forked processes (default and cap: `available_cpus()`);
    `on_result` sees each result as it arrives, in order (for progress reports)."""
    workers = min(len(jobs), workers or available_cpus(), available_cpus())
    if workers <= 1 or "fork" not in multiprocessing.get_all_start_methods():
        return _collect(map(fn, jobs), on_result)
    with worker_pool(workers, _set_jobs, (fn, jobs)) as pool:  # forked: fn and jobs are inherited, never pickled
        return _collect(pool.map(_run, range(len(jobs))), on_result)


def _collect(results: Iterator[Any], on_result: Callable[[Any], None] | None) -> list[Any]:
    out: list[Any] = []
    for result in results:
        out.append(result)
        if on_result is not None:
            on_result(result)
    return out
