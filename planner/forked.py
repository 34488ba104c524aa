"""Run independent jobs in forked worker processes that inherit the jobs (no pickling of models on the way in).

Fork, not spawn: workers start at once and share the parent's read-only models (pinocchio, coal);
only the results travel back, pickled. Falls back to running inline where fork is unavailable.
"""
from __future__ import annotations

import concurrent.futures
import multiprocessing
import os
from collections.abc import Callable, Sequence
from typing import Any

_JOBS: tuple[Callable[[Any], Any], Sequence[Any]] | None = None


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
    out: list[Any] = []
    if workers <= 1 or "fork" not in multiprocessing.get_all_start_methods():
        results = map(fn, jobs)
    else:
        _JOBS = (fn, jobs)
        pool = concurrent.futures.ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("fork"))
        results = pool.map(_run, range(len(jobs)))
    try:
        for result in results:
            out.append(result)
            if on_result is not None:
                on_result(result)
    finally:
        if workers > 1 and _JOBS is not None:
            pool.shutdown()
            _JOBS = None
    return out
