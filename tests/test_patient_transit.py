"""A transit the graph and its quick reconnections cannot find is searched again by a patient planner
(DoubleGraspPlanner.patiently), as the strategies plan the sequences that failed at a transit when none moved.

On the example session, the Rest transit is planned with a graph joined to its ends by one edge at most and no
reconnection left in the phase: the quick planner fails, the patient one finds it with RRTConnect given a whole
query's budget. The path found is checked independently: the robot's URDF geometry through python-fcl, against
the scene and the object at its final placement, every 0.01 rad.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from oracle import Oracle

from planner.collision.checker import build_collision_model
from planner.collision.situation import Situation
from planner.collision.validity import transit_profile
from planner.core.session import Session
from planner.motion.double_grasp import DoubleGraspPlanner
from planner.motion.graph import MotionGraph
from planner.motion.phase import Phase
from planner.motion.piece import PieceFailed
from planner.motion.result import MotionParams
from planner.motion.step import contact_profile
from planner.motion.transit_stage import transit_joints
from planner.motion.validities import Validities

EXAMPLE = Path(__file__).resolve().parent.parent / "sessions" / "default-example"
HURRIED = MotionParams(reconnect_motions=1, connections=1, max_connections=1, goal_nodes=1, max_searches=1, phase_reconnections=0)


def test_a_transit_the_quick_search_misses_is_found_patiently():
    session = Session.open(EXAMPLE)
    scene, roadmap, m = session.scene, session.result("roadmap"), session.result("motion")
    robot = scene.robot
    idx = transit_joints(robot)
    rest = np.flatnonzero(m.phase == list(m.phase_names).index("Rest"))
    qa = m.q[rest[0]]
    qb = qa.copy()
    qb[idx] = scene.q_final[idx]
    situation = Situation(None, scene.object_final)
    job = (Phase.REST, lambda stage: [stage.transit(qa, qb, situation)])

    def planner(patient: bool) -> DoubleGraspPlanner:
        validities = Validities(scene, build_collision_model(robot, scene.environment),
                                transit_profile(roadmap.resolution, HURRIED.transit_env_padding, HURRIED.transit_self_padding),
                                contact_profile(HURRIED))
        return DoubleGraspPlanner(scene, validities, MotionGraph(roadmap), HURRIED, np.random.default_rng(0), False, patient)

    quick = planner(False).transits([job])[0]
    assert isinstance(quick, PieceFailed), "the hurried search found the transit: nothing left to find patiently"

    patient = planner(True)
    found = patient.transits([job])[0]
    assert not isinstance(found, PieceFailed), f"not found patiently either: {found}"
    assert patient.stats[Phase.REST].rrt_calls > 0, "no patient reconnection was made"
    path = found[0].path
    assert np.allclose(path[0], qa) and np.allclose(path[-1], qb)
    oracle = Oracle(scene)
    for a, b in zip(path[:-1], path[1:]):
        for s in np.linspace(0.0, 1.0, max(2, int(np.ceil(np.abs(b - a).max() / 0.01)) + 1)):
            q = a + s * (b - a)
            hits = oracle.robot_collisions(q) + oracle.object_hits(q, scene.object_final)
            assert not hits, f"the patient transit collides: {hits}"
