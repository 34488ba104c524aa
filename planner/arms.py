"""The first step: which arm picks the object and which places it (each placement reached by one arm)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .collision import build_collision_model
from .errors import RegraspError
from .reach import reach
from .results import array
from .steps import Step, StepContext


@dataclass(frozen=True)
class ArmsParams:
    seeds: int = 32  # IK starts per arm and placement
    tolerance: float = 0.02  # m: grasp centre to the object's centre of mass
    picking_arm: str = ""  # force the picking arm (with placing_arm); empty: the one arm that reaches the initial placement
    placing_arm: str = ""


@dataclass(frozen=True)
class ArmAssignment:
    """The picking and placing arms, with a witness configuration of each reaching its placement."""

    picking_arm: str
    placing_arm: str
    distances: dict  # placement -> arm -> best distance (m)
    q_pick: np.ndarray = array("float64", ("nq",))
    q_place: np.ndarray = array("float64", ("nq",))

    def stats(self) -> dict:
        return {"picking_arm": self.picking_arm, "placing_arm": self.placing_arm}


def assign_arms(ctx: StepContext) -> ArmAssignment:
    scene, p = ctx.scene, ctx.params
    robot = scene.robot
    forced = (p.picking_arm, p.placing_arm)
    if any(forced):
        names = robot.spec.arm_names
        if not all(a in names for a in forced) or forced[0] == forced[1]:
            raise RegraspError(f"arms: picking_arm and placing_arm must be two different arms of the robot ({', '.join(names)}); "
                               f"got '{forced[0]}' and '{forced[1]}'")
    checker = build_collision_model(robot, scene.environment).checker()
    com = np.asarray(scene.object_mesh.center_mass)
    found, distances = {}, {}
    placements = {"initial": scene.object_initial, "final": scene.object_final}
    for i, (name, T) in enumerate(placements.items()):
        target = T[:3, :3] @ com + T[:3, 3]
        results = {}
        for j, arm in enumerate(robot.spec.arm_names):
            ctx.progress((2 * i + j) / 4, f"{arm} arm to the {name} placement")
            results[arm] = reach(robot, checker, arm, target, ctx.rng, p.seeds, p.tolerance)
        distances[name] = {a: r.distance for a, r in results.items()}
        chosen = p.picking_arm if name == "initial" else p.placing_arm
        if chosen:
            found[name] = results[chosen]  # the closest configuration is the witness even if the arm falls short
            continue
        arms = [a for a, r in results.items() if r.reachable]
        if len(arms) != 1:
            raise RegraspError(f"the {name} placement must be reachable by exactly one arm; reached by: {', '.join(arms) or 'none'}")
        found[name] = results[arms[0]]
    if found["initial"].arm == found["final"].arm:
        raise RegraspError(f"both placements are reached by the {found['initial'].arm} arm only: no regrasp is needed")
    ctx.progress(1.0, "done")
    return ArmAssignment(found["initial"].arm, found["final"].arm, distances, found["initial"].q, found["final"].q)


STEP = Step("arms", "which arm picks and which places", (), ArmsParams, ArmAssignment, assign_arms)
