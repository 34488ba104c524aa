"""Where a suite's jobs run: local worker processes (forked, dying with the suite), or Ray tasks on a local or remote cluster."""
from __future__ import annotations

import concurrent.futures
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from types import ModuleType

from planner.core.errors import RegraspError
from planner.core.forked import worker_pool
from planner.suite.job import JobResult, TaskJob, run_job

OnResult = Callable[[JobResult], None]


@dataclass(frozen=True)
class LocalExecutor:
    """Jobs on `workers` forked processes of this machine (each job's own pools stay within its `cpus`)."""

    workers: int

    def run(self, jobs: Sequence[TaskJob], on_result: OnResult, on_slots: Callable[[int], None]) -> None:
        """Run every job, handing each result to `on_result` as it arrives (in this process); `on_slots` hears how many run at once."""
        if not jobs:
            return
        on_slots(min(self.workers, len(jobs)))
        with worker_pool(min(self.workers, len(jobs))) as pool:
            futures = [pool.submit(run_job, job) for job in jobs]
            for future in concurrent.futures.as_completed(futures):
                on_result(future.result())


@dataclass(frozen=True)
class RayExecutor:
    """Jobs as Ray tasks (each asking for its job's CPUs): on the cluster at `address`, or on a local Ray started here when it is empty.

    A Ray already initialised in this process (e.g. by a test, with its own resources) is used as it is."""

    address: str

    def _ray(self) -> ModuleType:
        """The ray module (imported only when asked for: Ray is an optional extra)."""
        try:
            import ray
        except ImportError as exc:
            raise RegraspError("--ray needs Ray: pip install 'regrasp[cluster]' (or pip install ray)") from exc
        return ray

    def run(self, jobs: Sequence[TaskJob], on_result: OnResult, on_slots: Callable[[int], None]) -> None:
        """Submit every job, hand each result to `on_result` as it arrives; a Ray started here is shut down after."""
        ray = self._ray()
        started = not ray.is_initialized()
        if started:
            try:
                ray.init(address=self.address or None, include_dashboard=False, log_to_driver=False)
            except ConnectionError as exc:
                raise RegraspError(f"cannot reach the Ray cluster at {self.address}: {exc}") from exc
        try:
            on_slots(max(1, int(ray.cluster_resources().get("CPU", 1))))
            remote = ray.remote(run_job)
            pending = [remote.options(num_cpus=job.cpus).remote(job) for job in jobs]
            while pending:
                done, pending = ray.wait(pending, num_returns=1)
                for ref in done:
                    on_result(ray.get(ref))
        finally:
            if started:
                ray.shutdown()
