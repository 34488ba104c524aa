"""`regrasp bench grasps`: each hand's grasp list timed, side by side with the list builder of an earlier commit.

The earlier builder runs from a git worktree of that commit (made in a scratch folder and removed
after), in a subprocess whose PYTHONPATH is that worktree, on the same task, parameters and seed,
in turn with this code's builder (`repeat` times each; the fastest run counts). Neither reads a cached list; the object
model and the finger workspaces (whose code is the same in both) are made before either is timed.
Reported per hand: frames tried, frames left after each stage of the search, grasps, seconds (and
processor seconds, the builder's and its workers') and grasps per second, and the ratios of grasps per
second and per processor second to the earlier builder's.
"""
from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from planner.core.errors import RegraspError
from planner.grasping.finger_workspace import hand_workspaces
from planner.grasping.grasp_list import GraspParams, compute_grasp_list, search_object
from planner.grasping.object_model import mesh_bytes
from planner.grasping.search import OUTCOMES
from planner.model.hand_model import load_hand_model
from planner.model.task import Scene

BASELINE = "4a3c6ac"  # the last commit whose grasp search ran frame by frame (issue 38)
REPO = Path(__file__).resolve().parents[2]

# Run by the earlier code (its own modules, on its PYTHONPATH): one hand's list, timed, and the mesh's digest.
BASELINE_SCRIPT = """
import hashlib, json, os, sys, time
from planner.grasping.grasp_list import GraspParams, compute_grasp_list
from planner.grasping.object_model import mesh_bytes
from planner.model.task import load_task
a = json.loads(sys.argv[1])
scene = load_task(a["task"])
start, cpu = time.perf_counter(), sum(os.times()[:4])
r = compute_grasp_list(scene.robot.spec.arm(a["hand"]).hand, a["hand"], scene.object_mesh, GraspParams(**a["params"]), a["seed"],
                       workers=a["workers"])
print(json.dumps({"seconds": time.perf_counter() - start, "cpu_seconds": sum(os.times()[:4]) - cpu, "grasps": len(r),
                  "frames": r.frames_tried,
                  "outcomes": r.outcomes, "mesh": hashlib.sha256(mesh_bytes(scene.object_mesh)).hexdigest()}))
"""


@dataclass(frozen=True)
class HandBench:
    """One hand's list: this code's figures and, when measured, the earlier builder's."""

    hand: str
    frames: int
    stages: dict  # stage -> frames left after it, in search order
    grasps: int
    seconds: float
    cpu_seconds: float  # processor time of the builder and its workers: what a busy machine changes least
    baseline: dict | None  # the earlier builder's grasps, frames, seconds, cpu_seconds and outcomes

    @property
    def grasps_per_second(self) -> float:
        return self.grasps / max(self.seconds, 1e-9)

    @property
    def ratio(self) -> float | None:
        """Grasps per second over the earlier builder's (None without it)."""
        return self._ratio("seconds")

    @property
    def cpu_ratio(self) -> float | None:
        """Grasps per processor second over the earlier builder's (None without it)."""
        return self._ratio("cpu_seconds")

    def _ratio(self, field: str) -> float | None:
        if not self.baseline:
            return None
        return (self.grasps / max(getattr(self, field), 1e-9)) / max(self.baseline["grasps"] / max(self.baseline[field], 1e-9), 1e-9)


@dataclass(frozen=True)
class GraspBench:
    """The benchmark of one task: every hand asked for."""

    task: str
    seed: int
    workers: int
    repeat: int
    baseline_commit: str | None
    hands: list

    def to_dict(self) -> dict:
        return {"task": self.task, "seed": self.seed, "workers": self.workers, "repeat": self.repeat,
                "baseline_commit": self.baseline_commit,
                "hands": [{**asdict(h), "grasps_per_second": h.grasps_per_second, "ratio": h.ratio, "cpu_ratio": h.cpu_ratio}
                          for h in self.hands]}

    def render(self) -> str:
        out = [f"grasp lists of {self.task} (seed {self.seed}, {self.workers} worker(s), fastest of {self.repeat} run(s))"]
        for h in self.hands:
            out += ["", f"{h.hand} hand", f"{'frames tried':<34}{h.frames:>8}"]
            out += [f"{'  left after ' + stage:<34}{left:>8}" for stage, left in h.stages.items()]
            out += [f"{'grasps':<34}{h.grasps:>8}", f"{'seconds (processor seconds)':<34}{h.seconds:>8.2f}{h.cpu_seconds:>9.2f}",
                    f"{'grasps per second':<34}{h.grasps_per_second:>8.2f}"]
            if h.baseline:
                b = h.baseline
                out += [f"{self.baseline_commit} grasps, seconds, cpu s, grasps/s".ljust(34)
                        + f"{b['grasps']:>8}{b['seconds']:>9.2f}{b['cpu_seconds']:>9.2f}{b['grasps'] / max(b['seconds'], 1e-9):>9.2f}",
                        f"{'ratio of grasps per second':<34}{h.ratio:>8.2f}",
                        f"{'  per processor second':<34}{h.cpu_ratio:>8.2f}"]
        return "\n".join(out)


def stages(frames: int, outcomes: dict) -> dict:
    """Frames left after each stage of the search: each outcome but the last removes its frames."""
    left, out = frames, {}
    for name in OUTCOMES[:-1]:
        left -= outcomes.get(name, 0)
        out[name] = left
    return out


def baseline_worktree(commit: str, folder: Path) -> Path:
    """A detached git worktree of `commit` in `folder` (this checkout's repository); one line when git cannot make it."""
    path = folder / "baseline"
    done = subprocess.run(["git", "-C", str(REPO), "worktree", "add", "--detach", str(path), commit], capture_output=True, text=True)
    if done.returncode != 0:
        raise RegraspError(f"cannot check out the baseline commit '{commit}' from {REPO}: "
                           f"{(done.stderr.strip().splitlines() or ['git failed'])[-1]}")
    return path


def run_baseline(code: Path, task: Path, hand: str, params: dict, seed: int, workers: int) -> dict:
    """The earlier builder's figures for one hand, from a subprocess running the code in `code`."""
    env = {**os.environ, "PYTHONPATH": str(code)}
    arguments = json.dumps({"task": str(task), "hand": hand, "params": params, "seed": seed, "workers": workers})
    done = subprocess.run([sys.executable, "-c", BASELINE_SCRIPT, arguments], cwd=code, env=env, capture_output=True, text=True)
    if done.returncode != 0:
        raise RegraspError(f"the baseline builder failed on the {hand} hand: {(done.stderr.strip().splitlines() or ['?'])[-1]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def bench_grasps(scene: Scene, task: Path, hands: list[str], seed: int, workers: int, baseline: str | None, repeat: int = 1,
                 progress=print) -> GraspBench:
    """Time each hand's list with this code and (unless `baseline` is None) with the builder of commit `baseline`, each
    `repeat` times in turn (the fastest run of each counts: on a shared machine it is the steadiest figure)."""
    p = GraspParams()
    params = {name: getattr(p, name) for name in p.__dataclass_fields__}
    digest = hashlib.sha256(mesh_bytes(scene.object_mesh)).hexdigest()
    with tempfile.TemporaryDirectory(prefix="regrasp-bench-grasps-") as tmp:
        code = baseline_worktree(baseline, Path(tmp)) if baseline else None
        try:
            out = []
            for hand in hands:
                spec = scene.robot.spec.arm(hand).hand
                model = load_hand_model(spec)
                search_object(scene.object_mesh, [f.tip_radius for f in model.fingers], p)  # made (and cached) untimed
                hand_workspaces(model, p.workspace())
                before, seconds, cpu = None, float("inf"), float("inf")
                for run in range(repeat):  # the builders in turn; each keeps its fastest run
                    if code is not None:
                        progress(f"{hand} hand, run {run + 1}/{repeat}: the {baseline} builder ...")
                        figures = run_baseline(code, task, hand, params, seed, workers)
                        if figures.pop("mesh") != digest:
                            raise RegraspError(f"the baseline builder read another mesh for {task}")
                        if before is not None:  # the same list each run: the fastest times count
                            figures.update({t: min(figures[t], before[t]) for t in ("seconds", "cpu_seconds")})
                        before = figures
                    progress(f"{hand} hand, run {run + 1}/{repeat}: this builder ...")
                    start, processor = time.perf_counter(), sum(os.times()[:4])
                    result = compute_grasp_list(spec, hand, scene.object_mesh, p, seed, workers=workers)
                    seconds = min(seconds, time.perf_counter() - start)
                    cpu = min(cpu, sum(os.times()[:4]) - processor)
                out.append(HandBench(hand, result.frames_tried, stages(result.frames_tried, result.outcomes), len(result),
                                     seconds, cpu, before))
        finally:
            if code is not None:
                subprocess.run(["git", "-C", str(REPO), "worktree", "remove", "--force", str(code)], capture_output=True)
    return GraspBench(scene.name, seed, workers, repeat, baseline, out)
