"""`regrasp bench collision` and `bench double-grasps`: timings of the collision checker and forward kinematics and of the
online grasp steps (the motion step's benchmark is bench_motion.py)."""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np
import pinocchio as pin

from planner.collision.checker import build_collision_model
from planner.model.task import Scene


@dataclass(frozen=True)
class CollisionBench:
    """Per-call times in microseconds over collision-free configurations near the rest pose."""

    samples: int
    dof: int
    pairs_kept: int
    full_check_us_median: float
    full_check_us_p95: float
    arm_env_check_us_median: float
    arm_env_check_us_p95: float
    self_check_us_median: float
    fk_us_median: float

    def to_dict(self) -> dict:
        return asdict(self)

    def render(self) -> str:
        rows = [
            ("full check (self + environment)", self.full_check_us_median, self.full_check_us_p95),
            ("one arm + hand vs environment", self.arm_env_check_us_median, self.arm_env_check_us_p95),
            ("self-collision only", self.self_check_us_median, float("nan")),
            ("forward kinematics alone", self.fk_us_median, float("nan")),
        ]
        out = [f"{self.dof} DoF, {self.pairs_kept} pairs kept, {self.samples} collision-free configurations", "",
               f"{'what':<34}{'median µs':>11}{'p95 µs':>9}"]
        out += [f"{name:<34}{med:>11.1f}{p95:>9.1f}" for name, med, p95 in rows]
        return "\n".join(out)


def _times(fn, qs) -> np.ndarray:
    out = np.empty(len(qs))
    for i, q in enumerate(qs):
        t = time.perf_counter()
        fn(q)
        out[i] = time.perf_counter() - t
    return out * 1e6


def bench_collision(scene: Scene, samples: int = 2000, seed: int = 0) -> CollisionBench:
    """Time checks on collision-free configurations (the worst case: no early exit) near the rest pose."""
    robot = scene.robot
    cm = build_collision_model(robot, scene.environment)
    checker = cm.checker()
    rng = np.random.default_rng(seed)
    free = []
    while len(free) < samples:
        q = robot.clip(scene.q_initial + rng.normal(0.0, 0.3, robot.nq))
        if not checker.in_collision(q):
            free.append(q)
    arm = robot.spec.arm_names[0]
    for _ in range(2):  # warm up every subset's manager
        full = _times(checker.in_collision, free)
    arm_env = _times(lambda q: checker.in_collision(q, f"{arm}_env"), free)
    self_only = _times(lambda q: checker.in_collision(q, "self"), free)
    data = robot.model.createData()
    fk = _times(lambda q: pin.framesForwardKinematics(robot.model, data, q), free)
    return CollisionBench(
        samples=samples,
        dof=robot.nq,
        pairs_kept=len(cm.subsets["all"]),
        full_check_us_median=float(np.median(full)),
        full_check_us_p95=float(np.percentile(full, 95)),
        arm_env_check_us_median=float(np.median(arm_env)),
        arm_env_check_us_p95=float(np.percentile(arm_env, 95)),
        self_check_us_median=float(np.median(self_only)),
        fk_us_median=float(np.median(fk)),
    )


ONLINE_STEPS = ("grasp_configs", "exchange", "double_grasps")


@dataclass(frozen=True)
class DoubleGraspBench:
    """Seconds of the online grasp steps per run (the grasp lists and arms loaded from a session, not timed)."""

    runs: list  # per run: step name -> seconds
    double_grasps: list  # per run: how many were returned
    stages: list  # the last run's (step, stages)

    def to_dict(self) -> dict:
        return asdict(self)

    def render(self) -> str:
        from planner.core.stages import stage_table

        totals = [sum(r.values()) for r in self.runs]
        out = [f"{'step':<16}{'first run s':>12}{'median s':>10}{'max s':>8}"]
        for name in ONLINE_STEPS + ("total",):
            values = totals if name == "total" else [r[name] for r in self.runs]
            out.append(f"{name:<16}{values[0]:>12.3f}{float(np.median(values)):>10.3f}{max(values):>8.3f}")
        out += ["", f"double grasps returned per run: {', '.join(map(str, self.double_grasps))}", "", stage_table(self.stages)]
        return "\n".join(out)


def bench_double_grasps(scene: Scene, seed: int, repeat: int, folder, progress=print,
                        params: dict | None = None) -> DoubleGraspBench:
    """Run arms and both grasp lists once (from the cache when there), then the online steps `repeat` times on branches;
    `params`: step -> parameter overrides (`--set`), for every step."""
    from planner.core.runner import run_pipeline
    from planner.core.session import Session

    base = Session.create(folder / "base", scene, seed)
    progress("arms and grasp lists (from the user cache when computed before) ...")
    run_pipeline(base, until="place_grasps", params=params)
    runs, counts, stages = [], [], []
    for i in range(repeat):
        branch = base.branch(folder / f"run{i}", ONLINE_STEPS[0])
        run_pipeline(branch, until=ONLINE_STEPS[-1], params=params)
        runs.append({name: branch.record_of(name)["seconds"] for name in ONLINE_STEPS})
        counts.append(len(branch.result("double_grasps")))
        stages = [(name, branch.result(name).stages, branch.record_of(name).get("stage_seconds", [])) for name in ONLINE_STEPS]
        progress(f"run {i + 1}/{repeat}: {sum(runs[-1].values()):.3f} s, {counts[-1]} double grasps")
    return DoubleGraspBench(runs, counts, stages)
