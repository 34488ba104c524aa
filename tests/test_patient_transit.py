"""A transit the graph and its quick reconnections cannot find is searched again by a patient planner
(DoubleGraspPlanner.patiently), as the strategies plan the sequences that failed at a transit when none moved.

On the example session, a Rest transit (from the first of the Rest phase's early samples the quick planner cannot
leave) is planned with a graph joined to its ends by one edge at most and no reconnection left in the phase: the
quick planner fails, the patient one finds it with RRTConnect given a whole query's budget. The path found is
checked independently: the robot's URDF geometry through python-fcl, against the scene and the object at its final
placement, every 0.01 rad.
"""
from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
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


def _hurried_failure(session: Session) -> tuple[np.ndarray, np.ndarray, Situation]:
    """A Rest transit of the example the hurried planner cannot find: from the first of the samples in the first half
    of its Rest phase (every sixth: near the placement first) from which that planner cannot reach the final
    configuration of the arms and torso."""
    scene, m = session.scene, session.result("motion")
    idx, situation = transit_joints(scene.robot), Situation(None, scene.object_final)
    rest = np.flatnonzero(m.phase == list(m.phase_names).index("Rest"))
    for qa in m.q[rest[: len(rest) // 2: 6]]:
        qb = qa.copy()
        qb[idx] = scene.q_final[idx]
        job = (Phase.REST, lambda stage: [stage.transit(qa, qb, situation)])
        if isinstance(_planner(session, HURRIED).transits([job], [0])[0], PieceFailed):
            return qa, qb, situation
    pytest.fail("the hurried search found every Rest transit tried: nothing left to find patiently")


def _planner(session: Session, params: MotionParams, patient: bool = False) -> DoubleGraspPlanner:
    scene, roadmap = session.scene, session.result("roadmap")
    validities = Validities(scene, build_collision_model(scene.robot, scene.environment),
                            transit_profile(roadmap.resolution, params.transit_env_padding, params.transit_self_padding),
                            contact_profile(params))
    return DoubleGraspPlanner(scene, validities, MotionGraph(roadmap), params, np.random.default_rng(0), False, patient)


def test_a_transit_the_quick_search_misses_is_found_patiently():
    session = Session.open(EXAMPLE)
    scene = session.scene
    qa, qb, situation = _hurried_failure(session)
    job = (Phase.REST, lambda stage: [stage.transit(qa, qb, situation)])

    patient = _planner(session, HURRIED, patient=True)
    found = patient.transits([job], [0])[0]
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


def _given_up_first(first: MotionParams):
    """The example's sequences planned with `first`'s planner for the first one and the defaults after: (the attempt,
    the first planner)."""
    from planner.handover.grasp_configs import GraspConfigParams
    from planner.motion.strategies import plan_sequences

    session = Session.open(EXAMPLE)
    scene, roadmap = session.scene, session.result("roadmap")
    p = MotionParams(strategy="handover")
    made: list[DoubleGraspPlanner] = []

    def make(patient: bool) -> DoubleGraspPlanner:
        params = first if not made else p
        validities = Validities(scene, build_collision_model(scene.robot, scene.environment),
                                transit_profile(roadmap.resolution, params.transit_env_padding, params.transit_self_padding),
                                contact_profile(params))
        made.append(DoubleGraspPlanner(scene, validities, MotionGraph(roadmap), params, np.random.default_rng(0), False, patient))
        return made[-1]

    attempt = plan_sequences(make, scene, session.result("pick_grasps"), session.result("place_grasps"),
                             session.result("double_grasps"), (session.result("grasp_configs"), GraspConfigParams()),
                             None, p, np.random.default_rng(0), lambda *a: None)
    assert attempt.pieces is not None and attempt.tried[0], attempt.tried
    return attempt, made[0]


@pytest.mark.slow
def test_the_transits_of_a_sequence_given_up_are_counted():
    """The first double grasp is planned by a hurried planner, whose Rest transit fails: the sequence is given up and
    the next moves. The work of the one given up is not lost from the figures: the stage 'transits of the sequences
    given up' holds its planner's transit checks and pair tests, and the bench adds them to the run's."""
    from planner.cli.bench_motion import _given_up
    from planner.motion.strategies import GIVEN_UP

    attempt, hurried = _given_up_first(HURRIED)
    assert "transit" in attempt.tried[0], attempt.tried
    checks, pairs = sum(s.checks for s in hurried.stats), sum(s.pair_tests for s in hurried.stats)
    assert checks > 0 and pairs > 0
    stage = next(s for s in attempt.stages if s["stage"] == GIVEN_UP)
    assert (stage["checks"], stage["count"]) == (checks, pairs)
    assert len(attempt.seconds) == len(attempt.stages)  # the stage's seconds are where the stage table reads them
    given = _given_up(SimpleNamespace(stages=attempt.stages), attempt.seconds)
    assert (given["checks"], given["pair_tests"]) == (checks, pairs) and given["seconds"] > 0


@pytest.mark.slow
def test_a_sequence_given_up_before_its_transits_adds_no_stage():
    """The first double grasp's contact motions fail (obstacles kept 5 cm away: the hand cannot reach the object), so no
    transit of it ran: no stage counts its transits, and no stage of the motion counts 0 (a suite names the first stage
    that kept nothing as where a failed step stopped)."""
    from planner.cli.bench_motion import _given_up
    from planner.motion.strategies import GIVEN_UP

    attempt, padded = _given_up_first(MotionParams(contact_env_padding=0.05, contact_env_clearance=0.04))
    assert "transit" not in attempt.tried[0] and sum(s.checks for s in padded.stats) == 0, attempt.tried
    assert all(s["stage"] != GIVEN_UP and s["count"] > 0 for s in attempt.stages if s["stage"] != "regrasp graph")
    assert _given_up(SimpleNamespace(stages=attempt.stages), attempt.seconds) == {"checks": 0, "pair_tests": 0, "seconds": 0.0}


def test_a_graph_query_left_without_reconnections_says_why():
    """A Rest transit of the example planned hurriedly fails; its failure names the phase's RRTConnect budget when none is
    left: none given (phase_reconnections 0), or spent by an earlier transit of the phase (1, taken by the first try,
    which it lets succeed)."""
    from dataclasses import replace

    session = Session.open(EXAMPLE)
    qa, qb, situation = _hurried_failure(session)

    def failures(params: MotionParams) -> list[str]:
        """The transit searched twice, each time on its own copy of the graph (the first's reconnection does not join
        the second's), the phase's figures shared."""
        planner, out = _planner(session, params), []
        for _ in range(2):
            try:
                planner.stage(Phase.REST, graph=planner.graph.copy()).transit(qa, qb, situation)
                out.append("")
            except PieceFailed as exc:
                out.append(exc.why)
        return out

    first, second = failures(HURRIED)
    assert "0 RRT reconnections (motion.phase_reconnections is 0: no RRTConnect reconnection)" in first, first
    first, second = failures(replace(HURRIED, phase_reconnections=1))
    assert first == "", first  # found with the phase's one reconnection, which the second try then lacks
    assert second.endswith("0 RRT reconnections (the phase's 1 RRTConnect call (motion.phase_reconnections) went to its "
                           "earlier transits)"), second
