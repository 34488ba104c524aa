"""Worker processes never outlive their parent: `regrasp plan` and the workbench's background runs, killed with
SIGKILL or stopped with SIGTERM during the grasp search, leave no worker running (checked by PID through /proc)."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from sandbox import cli_env
from test_workbench_browser import _free_port, _wait_for

from planner.core.session import Session

pytestmark = pytest.mark.slow  # each test starts and signals whole planner processes

WORKERS_START_WITHIN = 900.0  # s: a cold cache builds the pair set, the finger workspaces and the object model first
WORKERS_GONE_WITHIN = 30.0  # s: a timeout, not a measurement; the kernel kills them at once


@pytest.fixture(autouse=True)
def every_core():
    """The in-process pools here fork two workers, whatever budget the test worker runs under (conftest.py)."""
    from planner.core.forked import cpu_budget

    with cpu_budget(2):
        yield


WORKBENCH_RUN = """
import faulthandler
import signal
import sys
from pathlib import Path
from workbench import app

faulthandler.register(signal.SIGUSR1, all_threads=True)  # where every thread is, should it not stop (see _stopped)


class Running(app.Workbench):
    def __init__(self, *args, **kwargs):
        super().__init__(*args, sessions_dir=Path(sys.argv[2]), **kwargs)  # where a stopped run's steps are kept
        self.session_panel.run_until("pick_grasps")


app.Workbench = Running
app.run(None, "127.0.0.1", int(sys.argv[1]))
"""


def _children(pid: int) -> set[int]:
    """The direct children of a process (every thread's), from /proc."""
    out: set[int] = set()
    for f in Path(f"/proc/{pid}/task").glob("*/children"):
        try:
            out |= {int(c) for c in f.read_text().split()}
        except OSError:  # the thread ended meanwhile
            pass
    return out


def _running(pid: int) -> bool:
    """Whether a process exists and is not a zombie (a container's init may never reap re-parented ones)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state not in ("Z", "X")


@pytest.fixture(scope="module")
def cold_cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A cache of this module's own: no grasp list is ever in it (every run here is killed), so the search always runs."""
    return tmp_path_factory.mktemp("orphan-cache")


@pytest.fixture
def started(cold_cache: Path, tmp_path: Path) -> Iterator[Callable[[list[str]], tuple[subprocess.Popen, set[int]]]]:
    """Start a command and wait until it has forked its grasp-search workers; killed at the end if still running."""
    procs: list[subprocess.Popen] = []
    seen: set[int] = set()

    def start(command: list[str]) -> tuple[subprocess.Popen, set[int]]:
        proc = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=tmp_path,
                                env=cli_env(REGRASP_CACHE=str(cold_cache)))
        procs.append(proc)
        assert _wait_for(lambda: len(_children(proc.pid)) >= 2 or proc.poll() is not None, WORKERS_START_WITHIN)
        workers = _children(proc.pid)
        seen.update(workers)
        assert proc.poll() is None and len(workers) >= 2, proc.stderr.read() if proc.stderr else ""
        return proc, workers

    yield start
    for proc in procs:  # whatever a failed test left: the process it started, then the workers seen, by PID
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    for pid in seen:
        if _running(pid):
            os.kill(pid, signal.SIGKILL)


def _plan(out: Path) -> list[str]:
    return [sys.executable, "-m", "workbench.cli", "plan", "default", "--out", str(out)]


def _workbench(sessions: Path) -> list[str]:
    return [sys.executable, "-c", WORKBENCH_RUN, str(_free_port()), str(sessions)]


@pytest.mark.parametrize("command", ["plan", "workbench"])
def test_sigkill_leaves_no_worker(started, tmp_path: Path, command: str) -> None:
    proc, workers = started(_plan(tmp_path / "s") if command == "plan" else _workbench(tmp_path / "sessions"))
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert _wait_for(lambda: not any(_running(w) for w in workers), WORKERS_GONE_WITHIN), \
        f"workers {sorted(w for w in workers if _running(w))} outlived their killed parent"


def test_sigterm_of_plan_stops_its_workers_with_a_message(started, tmp_path: Path) -> None:
    out = tmp_path / "s"
    proc, workers = started(_plan(out))
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=120) == 128 + signal.SIGTERM
    stderr = proc.stderr.read() if proc.stderr else ""
    assert "Traceback" not in stderr and "error: terminated (SIGTERM)" in stderr, stderr
    assert not any(_running(w) for w in workers)
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] == [], "a temporary file was left in the session"
    assert [p.name for p in tmp_path.iterdir()] == ["s"], "the run wrote beside its session folder"


def _stopped(proc: subprocess.Popen, timeout: float) -> int:
    """The exit code of a workbench process asked to stop; if it has not stopped within `timeout`, the test fails with
    every thread's stack (the workbench script dumps them on SIGUSR1)."""
    try:
        return proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.send_signal(signal.SIGUSR1)
        time.sleep(2.0)
        proc.kill()
        _, stderr = proc.communicate()
        pytest.fail(f"the workbench did not stop within {timeout:.0f} s; its threads:\n{stderr}")


def test_sigterm_of_the_workbench_stops_a_running_steps_workers(started, tmp_path: Path) -> None:
    proc, workers = started(_workbench(tmp_path / "sessions"))
    proc.send_signal(signal.SIGTERM)
    assert _stopped(proc, 120) == 0
    stderr = proc.stderr.read() if proc.stderr else ""
    assert "Traceback" not in stderr, stderr
    assert not any(_running(w) for w in workers)
    kept = tmp_path / "sessions" / "default-unsaved-1"  # the step the stopped run had finished (arms), kept
    assert [p.name for p in (tmp_path / "sessions").iterdir()] == [kept.name] and Session.open(kept).finished() == ["arms"]


def test_worker_pool_kills_its_workers_when_the_caller_raises() -> None:
    """In process: an exception (Ctrl-C, SIGTERM) in the parent kills the pool's workers instead of waiting for their jobs."""
    from planner.core.forked import worker_pool

    before, threads = _children(os.getpid()), set(threading.enumerate())
    with pytest.raises(KeyboardInterrupt), worker_pool(2) as pool:
        for _ in range(2):
            pool.submit(time.sleep, 600)
        assert _wait_for(lambda: len(_children(os.getpid()) - before) >= 2, 60)
        workers = _children(os.getpid()) - before
        raise KeyboardInterrupt
    assert not any(_running(w) for w in workers)
    # nor its manager thread: at exit CPython writes to the wake-up pipe of one still running, which it may have closed
    # ("Bad file descriptor" printed by a `regrasp plan` stopped with SIGTERM in CI)
    assert set(threading.enumerate()) - threads == set(), "the pool left a thread running"


def test_sigterm_while_a_pool_forks_kills_every_worker() -> None:
    """SIGTERM right after a pool's second fork (before CPython enters that worker in the pool's map): the pool has killed
    and reaped both workers when the exception leaves it (a worker left to die later outlived `regrasp plan` in CI)."""
    from planner.core.forked import Terminated, sigterm_unwinds, worker_pool

    before = _children(os.getpid())
    forked: list[set[int]] = []
    armed = [True]

    def after_fork() -> None:
        if armed[0]:
            forked.append(_children(os.getpid()) - before)
            if len(forked) == 2:
                armed[0] = False
                os.kill(os.getpid(), signal.SIGTERM)

    os.register_at_fork(after_in_parent=after_fork)  # it cannot be removed: disarmed once it has fired
    try:
        with pytest.raises(Terminated), sigterm_unwinds(), worker_pool(2) as pool:
            pool.submit(time.sleep, 600)
    finally:
        armed[0] = False
    workers = forked[-1]
    left = sorted(w for w in workers if Path(f"/proc/{w}").exists())
    assert len(workers) == 2 and left == [], f"workers {left} not reaped by the pool"


def test_a_stopped_thread_starts_no_new_pool() -> None:
    """stop_pools between two of a thread's pools (none live to kill): the thread's next pool is refused, not forked (at
    exit CPython waits for every pool's jobs: a stopped workbench stayed up for minutes)."""
    from planner.core.forked import Stopped, stop_pools, worker_pool

    before, stopped, outcome = _children(os.getpid()), threading.Event(), []

    def body() -> None:
        stopped.wait(60)
        try:
            with worker_pool(2) as pool:
                outcome.append(list(pool.map(abs, [-1, -2])))
        except Stopped:
            outcome.append("stopped")

    thread = threading.Thread(target=body)
    thread.start()
    stop_pools(thread)
    stopped.set()
    thread.join(60)
    assert outcome == ["stopped"]
    assert _children(os.getpid()) - before == set()
