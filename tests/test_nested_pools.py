"""Nested worker pools (a job on a worker makes a pool of its own) end, and a CPU budget bounds what a pool forks."""
from __future__ import annotations

import subprocess
import sys
import textwrap

from planner.core.forked import available_cpus, cpu_budget, executor, forked_map

REPRODUCTION = textwrap.dedent("""
    from planner.core.forked import worker_pool, forked_map

    def inner(_):
        return forked_map(abs, [-1, -2, -3], workers=2)   # a job that uses worker processes itself, as a suite task does

    if __name__ == "__main__":
        with worker_pool(1) as pool:
            print(pool.submit(inner, None).result(timeout=30))
    """)


def test_a_job_on_a_worker_may_use_worker_processes_itself(tmp_path):
    """Issue 40's reproduction: the child no longer waits on the lock its parent held while forking it (a hang before)."""
    script = tmp_path / "nested.py"
    script.write_text(REPRODUCTION)
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[1, 2, 3]"


def _pid(_: object) -> int:
    import os

    return os.getpid()


def test_a_budget_of_one_cpu_runs_jobs_inline_and_bounds_every_pool():
    import os

    with cpu_budget(1):
        assert available_cpus() == 1
        assert set(forked_map(_pid, range(6), workers=4)) == {os.getpid()}  # no process forked
        with executor(4) as pool:
            assert pool.submit(_pid, None).result() == os.getpid()
    with cpu_budget(2):
        pids = set(forked_map(_pid, range(40), workers=8))
        assert os.getpid() not in pids and len(pids) <= 2
