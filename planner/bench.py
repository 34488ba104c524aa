"""`regrasp bench collision`: timings of the collision checker and of forward kinematics."""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np
import pinocchio as pin

from .collision import build_collision_model
from .task import Scene


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
