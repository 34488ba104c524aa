"""Lazy transit on the Super Graph, with RRTConnect reconnecting what the graph cannot.

The lazy-transit test uses the example session's Super Graph and puts the statuette, as a static
obstacle, in the middle of the path the graph returns without it: the planner must search again and
come back with a path that an independent re-check (the robot's URDF geometry against the object with
python-fcl, every segment at ten times the resolution of the object's pairs) finds free. The carried
test does the same with the object hanging from a palm, and shows once that the independent check
catches a planner whose model is blind to the carried object's obstacles.
"""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from oracle import Oracle

from planner.motion.result import MotionParams
from planner.motion.space import JointSpace
from planner.motion.transit import TransitParams

TRANSIT = TransitParams.of(MotionParams())
EXAMPLE = Path(__file__).resolve().parent.parent / "sessions" / "default-example"


def phase_planner(scene, roadmap, baseline: bool = False):
    """The planner of a double grasp on a scene and the roadmap, with the default parameters and seed 0."""
    from planner.collision.checker import build_collision_model
    from planner.collision.validity import transit_profile
    from planner.motion.double_grasp import DoubleGraspPlanner
    from planner.motion.graph import MotionGraph
    from planner.motion.step import contact_profile
    from planner.motion.validities import Validities

    p = MotionParams()
    validities = Validities(scene, build_collision_model(scene.robot, scene.environment),
                            transit_profile(roadmap.resolution, p.transit_env_padding, p.transit_self_padding), contact_profile(p))
    return DoubleGraspPlanner(scene, validities, MotionGraph(roadmap), p, np.random.default_rng(0), baseline)


def example_inputs(tmp_path_factory) -> tuple:
    """(scene, roadmap, pick grasp list) of a copy of the example session: what the motion tests here and in
    test_finger_motions.py, test_clearances.py and test_transit_checks.py plan on."""
    from planner.core.session import Session

    folder = tmp_path_factory.mktemp("motion") / "example"
    shutil.copytree(EXAMPLE, folder)
    s = Session.open(folder)
    return s.scene, s.result("roadmap"), s.result("pick_grasps")


@pytest.fixture(scope="module")
def example(tmp_path_factory):
    return example_inputs(tmp_path_factory)


@pytest.mark.slow
def test_lazy_transit_goes_around_the_object(example):
    from planner.collision.checker import build_collision_model
    from planner.collision.shapes import coal_mesh
    from planner.collision.situation import Situation, situation_model
    from planner.collision.validity import make_validity, transit_profile
    from planner.motion.graph import MotionGraph
    from planner.motion.transit import LazyTransit, TransitStats

    scene, roadmap, _ = example
    robot = scene.robot
    cm = build_collision_model(robot, scene.environment)
    idx = np.concatenate([robot.torso_idx] + [robot.arm_idx[a] for a in robot.spec.arm_names])
    profile = transit_profile(roadmap.resolution, 0.02, 0.008)
    shape = coal_mesh(scene.object_mesh)
    big = int(np.bincount(roadmap.node_component).argmax())
    nodes = np.flatnonzero(roadmap.node_component == big)
    from planner.motion.transit import TransitFailed

    far = np.argsort(-np.linalg.norm(roadmap.wrists[nodes, 0] - roadmap.wrists[nodes[0], 0], axis=1), kind="stable")
    q_start = scene.q_initial
    space = JointSpace.of(robot.lower, robot.upper, idx, q_start)
    free = make_validity(situation_model(cm, shape, Situation(None, np.diag([1.0, 1, 1, 1]) @ _far()), (), idx), profile, "moving")
    data = robot.model.createData()

    def around(q_goal: np.ndarray):
        """(first path, the object's pose where its wrist passes half way, the configuration there, the path around
        it and its stats), None when either query finds no path."""
        try:
            first = LazyTransit(MotionGraph(roadmap), space, free.on("changed"), free, free, TRANSIT, np.random.default_rng(0),
                                TransitStats()).query(q_start, q_goal)
            mid = first[len(first) // 2]
            pin.framesForwardKinematics(robot.model, data, mid)
            wrist = data.oMf[robot.frame_id(robot.spec.arm(robot.spec.arm_names[0]).hand.mount_frame)].translation
            pose = np.eye(4)
            pose[:3, 3] = wrist - np.asarray(scene.object_mesh.center_mass)
            blocked = make_validity(situation_model(cm, shape, Situation(None, pose), (), idx), profile, "moving")
            if blocked.state_valid(mid):
                return None  # the object must block the first path
            stats = TransitStats()
            path = LazyTransit(MotionGraph(roadmap), space, blocked.on("changed"), blocked, blocked, TRANSIT,
                               np.random.default_rng(0), stats).query(q_start, q_goal)
            return pose, mid, blocked, path, stats
        except TransitFailed:
            return None

    # the wrist's farthest node of the largest component that the start joins and whose path can go around the object
    found = next((r for r in (around(roadmap.node_q[nodes[k]]) for k in far[:10]) if r is not None), None)
    assert found is not None, "no far node of the largest component is joined around the object"
    pose, mid, blocked, path, stats = found
    q_goal = path[-1]
    assert stats.searches > 1, "the first path must have been rejected and the graph searched again"
    assert not np.any(np.all(np.isclose(path, mid), axis=1)), "the blocked configuration is not on the new path"
    assert np.allclose(path[0], q_start) and np.allclose(path[-1], q_goal)
    oracle = Oracle(scene)
    for a, b in zip(path[:-1], path[1:]):
        for s in np.linspace(0, 1, 10 * blocked.samples(a, b, "object")):
            q = a + s * (b - a)
            assert not oracle.object_hits(q, pose)


def _far() -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = [5.0, 5.0, 5.0]
    return T


@pytest.mark.slow
def test_rrt_reconnects_what_the_graph_cannot(example):
    """With every roadmap edge gone, start and goal far apart share no neighbour: only RRTConnect can join them, and its
    path joins the graph."""
    import dataclasses

    from planner.collision.checker import build_collision_model
    from planner.collision.shapes import coal_mesh
    from planner.collision.situation import Situation, situation_model
    from planner.collision.validity import make_validity, transit_profile
    from planner.motion.graph import MotionGraph
    from planner.motion.transit import LazyTransit, TransitStats

    scene, roadmap, _ = example
    robot = scene.robot
    cut = dataclasses.replace(roadmap, edge_valid=np.zeros(len(roadmap.edges), dtype=bool))
    idx = np.concatenate([robot.torso_idx] + [robot.arm_idx[a] for a in robot.spec.arm_names])
    space = JointSpace.of(robot.lower, robot.upper, idx, scene.q_initial)
    cm = build_collision_model(robot, scene.environment)
    validity = make_validity(situation_model(cm, coal_mesh(scene.object_mesh), Situation(None, _far()), (), idx),
                             transit_profile(roadmap.resolution, 0.02, 0.008), "moving")
    q_start = scene.q_initial
    far = np.argsort(-space.distance(roadmap.node_q, q_start), kind="stable")[:200]
    # the farthest node the straight motion from the start cannot reach (the direct join is tried first)
    q_goal = roadmap.node_q[next(int(k) for k in far if not validity.motion_valid(q_start, roadmap.node_q[k]))]
    graph, stats = MotionGraph(cut), TransitStats()
    edges_before = len(graph.edges)
    narrow = dataclasses.replace(TRANSIT, max_connections=8)
    path = LazyTransit(graph, space, validity.on("changed"), validity, validity, narrow, np.random.default_rng(1),
                       stats).query(q_start, q_goal)
    assert stats.rrt_calls >= 1 and stats.nodes_validating > 0
    assert len(graph.edges) > edges_before + 16, "the reconnection's path joined the graph"
    assert np.allclose(path[0], q_start) and np.allclose(path[-1], q_goal)
    assert validity.path_valid(path) and all(space.holds(q) for q in path)


@pytest.fixture(scope="module")
def carried(example):
    """A goal the graph is searched for from q_initial, and a hold (the object 25 cm out of a palm along one of its axes)
    free at both ends but hit along the path the graph returns for the robot alone."""

    from planner.collision.checker import build_collision_model
    from planner.collision.shapes import coal_mesh
    from planner.collision.situation import Situation, situation_model
    from planner.collision.validity import make_validity, transit_profile
    from planner.motion.graph import MotionGraph
    from planner.motion.transit import LazyTransit, TransitStats

    scene, roadmap, _ = example
    robot = scene.robot
    arm = robot.spec.arm_names[0]
    cm = build_collision_model(robot, scene.environment)
    idx = np.concatenate([robot.torso_idx] + [robot.arm_idx[a] for a in robot.spec.arm_names])
    shape = coal_mesh(scene.object_mesh)
    oracle = Oracle(scene)
    data = robot.model.createData()
    palm_frame = robot.frame_id(robot.palm_frame(arm))

    def palm(q):
        pin.framesForwardKinematics(robot.model, data, q)
        return data.oMf[palm_frame].homogeneous

    big = int(np.bincount(roadmap.node_component).argmax())
    nodes = np.flatnonzero(roadmap.node_component == big)
    q_start = scene.q_initial
    space = JointSpace.of(robot.lower, robot.upper, idx, q_start)
    profile = transit_profile(roadmap.resolution, 0.02, 0.008)
    free = make_validity(situation_model(cm, shape, Situation(None, _far()), (), idx), profile, "moving")
    for goal_node in nodes[np.argsort(-space.distance(roadmap.node_q[nodes], q_start))][:400]:
        q_goal = roadmap.node_q[goal_node]
        if free.motion_valid(q_start, q_goal):
            continue  # a straight line: the graph is not searched
        alone = LazyTransit(MotionGraph(roadmap), space, free.on("changed"), free, free, TRANSIT, np.random.default_rng(0),
                            TransitStats()).query(q_start, q_goal)
        for axis in np.vstack([np.eye(3), -np.eye(3)]):
            hold = np.eye(4)
            hold[:3, 3] = -0.25 * axis  # palm in the object's frame: the object 25 cm along `axis` from the palm
            at = lambda q, hold=hold: palm(q) @ np.linalg.inv(hold)  # noqa: E731
            if any(oracle.collisions(q, at(q), arm, None, False) for q in (q_start, q_goal)):
                continue
            if any(oracle.collisions(q, at(q), arm, None, False) for a, b in zip(alone[:-1], alone[1:]) for q in np.linspace(a, b, 5)):
                return {"arm": arm, "q_start": q_start, "q_goal": q_goal, "hold": hold, "at": at, "space": space, "cm": cm,
                        "shape": shape, "idx": idx, "profile": profile, "oracle": oracle}
    pytest.fail("no goal and hold whose object-free path sweeps the carried object through something")


def _carried_validity(case):
    """The planner's validity of the carried case (its model as `situation.situation_model` makes it at the call)."""
    from planner.collision.situation import Situation, situation_model
    from planner.collision.validity import make_validity

    c = case
    return make_validity(situation_model(c["cm"], c["shape"], Situation(c["arm"], c["hold"]), (), c["idx"]), c["profile"], "moving")


def _independent_hits(case, validity, path: np.ndarray, first: bool = False) -> list[str]:
    """What the independent check finds along a path of the carried case, at ten times the resolution of the object's
    pairs (with `first`, up to the first configuration where it finds something)."""
    c = case
    found = (c["oracle"].collisions(a + s * (b - a), c["at"](a + s * (b - a)), c["arm"], None, False)
             for a, b in zip(path[:-1], path[1:]) for s in np.linspace(0, 1, 10 * validity.samples(a, b, "object")))
    return next((h for h in found if h), []) if first else [hit for h in found for hit in h]


def _carry(example, case) -> tuple[object, object, np.ndarray]:
    """The lazy transit of the carried case: (the validity it was planned with, the transit's stats, its path)."""
    from planner.motion.graph import MotionGraph
    from planner.motion.transit import LazyTransit, TransitStats

    _, roadmap, _ = example
    c = case
    validity = _carried_validity(c)
    stats = TransitStats()
    path = LazyTransit(MotionGraph(roadmap), c["space"], validity.on("changed"), validity, validity, TRANSIT,
                       np.random.default_rng(0), stats).query(c["q_start"], c["q_goal"])
    assert np.allclose(path[0], c["q_start"]) and np.allclose(path[-1], c["q_goal"])
    return validity, stats, path


@pytest.mark.slow
def test_lazy_transit_goes_around_with_the_carried_object(example, carried):
    """The carried object cuts the path the graph gives the robot alone: the lazy search invalidates what it hits and goes
    around, and the independent check (URDF meshes and the carried object with python-fcl) finds the new path free."""
    validity, stats, path = _carry(example, carried)
    hits = _independent_hits(carried, validity, path)
    assert stats.edges_invalidated + stats.rrt_calls > 0, "the carried object must have cut the robot-alone path"
    assert hits == []


def _probe_beside_the_robot(scene, case, path: np.ndarray):
    """(the environment with a 1 cm ball 'probe' on the carried object's surface at a configuration of the path, its
    collision model, the case's validity in it) such that the validity passes the path: the robot itself never comes
    near the ball. Tried from the path's middle outwards, the object's points farthest from the palm first; None when
    none is found."""
    from planner.collision.checker import build_collision_model
    from planner.model.environment import Obstacle

    dense = np.concatenate([np.linspace(a, b, 8, endpoint=False) for a, b in zip(path[:-1], path[1:])])
    order = np.argsort(np.abs(np.arange(len(dense)) - len(dense) / 2), kind="stable")
    for q in dense[order[::4]][:8]:
        pose = case["at"](q)
        vertices = np.asarray(scene.object_mesh.vertices) @ pose[:3, :3].T + pose[:3, 3]
        palm = (pose @ case["hold"])[:3, 3]
        for v in np.argsort(-np.linalg.norm(vertices - palm, axis=1))[:40:10]:
            probe = np.eye(4)
            probe[:3, 3] = vertices[v]
            environment = scene.environment + (Obstacle("probe", "sphere", (0.01,), probe),)
            cm = build_collision_model(scene.robot, environment)
            validity = _carried_validity(dict(case, cm=cm))
            if validity.path_valid(path):
                return environment, cm, validity
    return None


@pytest.mark.slow
def test_the_independent_check_catches_a_checker_blind_to_the_carried_object(example, carried, monkeypatch):
    """The planner's model broken on purpose (the carried object no longer checked against the obstacles) plans the
    carried transit; a small ball is then put as an obstacle on the object's surface half way along that path. The
    broken checker still passes the path (a planner using it lets the object through the ball), the planner's own
    checker does not, and the independent check must find the object in an obstacle (the ball, or one the path already
    carried it through)."""
    import dataclasses

    import planner.collision.situation as situation

    original = situation.situation_model

    def blind(cm, shape, s, moved, moving):
        model = original(cm, shape, s, moved, moving)
        obstacles = len(cm.geometry.geometryObjects) - cm.n_robot_geoms
        object_env = model.subsets["env"][-obstacles:]  # the carried object's pairs with the obstacles come last
        return dataclasses.replace(model, subsets={**model.subsets, "moving": np.setdiff1d(model.subsets["moving"], object_env)})

    monkeypatch.setattr(situation, "situation_model", blind)
    scene = example[0]
    _, _, path = _carry(example, carried)
    found = _probe_beside_the_robot(scene, carried, path)
    assert found is not None, "no point of the object's surface along the path that the robot itself keeps clear of"
    environment, cm, broken = found
    probed = dict(carried, cm=cm, oracle=Oracle(dataclasses.replace(scene, environment=environment)))
    monkeypatch.setattr(situation, "situation_model", original)
    assert not _carried_validity(probed).path_valid(path), "the planner's own checker must see the object hit the ball"
    hits = _independent_hits(probed, broken, path, first=True)
    assert any(h.startswith("the object with") for h in hits), f"a checker blind to the carried object's obstacles went unnoticed ({hits})"
