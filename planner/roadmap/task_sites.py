"""Where a task's transit queries start and end, known before any grasp is chosen: the roadmap is made dense there.

The online transits (paper V-B) join the rest configurations, the hands at the placements (their pre-grasps, lifts and
set-downs lie a few centimetres from the object) and the exchange. Offline, each arm's sites are its torso and arm
values at the initial and final configurations, at the placements it reaches (its fingertip centre brought above the
object's centre of mass), and at the exchange point: the geometric median of the palms' stops, where the
exchange grid's cost (paper V-C, fig. 6) is lowest when obstacles allow.
"""
from __future__ import annotations

import numpy as np

from planner.collision.checker import CollisionChecker
from planner.handover.arms import decide, geometric_median
from planner.handover.exchange import palm_waypoints
from planner.handover.reach import fingertip_centre, placement_reach, solve_position
from planner.model.task import Scene
from planner.roadmap.decomposition import Decomposition

HEIGHTS = (0.05, 0.12)  # m: targets above the object's centre of mass at a placement, where pre-grasps, lifts and set-downs
# bring the hand (at the centre itself the open hand would be in the support, closer than the roadmap's paddings)
TOLERANCE = 0.03  # m: an IK solution counts when its fingertip centre comes this near its target
SPREAD = 0.5  # rad: IK starts around the initial configuration (the online grasp configurations' arms are natural ones)


def task_sites(scene: Scene, dec: Decomposition, checker: CollisionChecker, starts: int,
               rng: np.random.Generator) -> dict[str, np.ndarray]:
    """arm -> (k, sub-system dims) its sites' values of the common part and the arm (see the module), unchecked: the
    roadmap keeps those free at its paddings; IK per target from the configuration that reached it, from the initial
    one and from `starts` random ones around that.
    `checker`: the scene's model at the task check's paddings, which decide what each arm reaches."""
    robot = scene.robot
    reaches = placement_reach(scene, checker)
    com = np.asarray(scene.object_mesh.center_mass)
    placements = {name: T[:3, :3] @ com + T[:3, 3] for name, T in (("initial", scene.object_initial), ("final", scene.object_final))}
    targets: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {arm: [] for arm in dec.arms}  # (target, IK start)
    for name, centre in placements.items():
        for arm, r in reaches[name].items():
            if r.reachable:
                targets[arm] += [(centre + [0.0, 0.0, h], r.q) for h in HEIGHTS]
    decision = decide(scene, reaches)
    if decision.handover and not decision.failure:
        a, b = decision.picking_arm, decision.placing_arm
        w = palm_waypoints(scene, a, b, reaches["initial"][a].q, reaches["final"][b].q)
        exchange = geometric_median(np.array([w.pick_grasp, w.pick_final, w.place_initial, w.place_place]))
        for arm in (a, b):
            targets[arm].append((exchange, scene.q_initial))
    out = {}
    for arm in dec.arms:
        idx = dec.subsystem(arm)
        found = [scene.q_initial, scene.q_final]
        offset = fingertip_centre(robot, arm)
        for target, start in targets[arm]:
            for s in range(starts + 2):
                q0 = dec.q_hold.copy()
                q0[idx] = (start[idx] if s == 0 else scene.q_initial[idx] if s == 1 else
                           np.clip(scene.q_initial[idx] + rng.normal(0.0, SPREAD, len(idx)), robot.lower[idx], robot.upper[idx]))
                q = solve_position(robot, arm, target, q0, offset)
                tip = robot.frame_placement(q, robot.palm_frame(arm))
                if np.linalg.norm(tip[:3, :3] @ offset + tip[:3, 3] - target) <= TOLERANCE:
                    found.append(q)
        out[arm] = np.array([q[idx] for q in found])
    return out
