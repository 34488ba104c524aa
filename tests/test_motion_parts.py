"""The motion's building blocks: timing under limits, the joint space, the object in the collision model, lazy transit.

The lazy-transit test uses the example session's Super Graph and puts the statuette, as a static
obstacle, in the middle of the path the graph returns without it: the planner must search again and
come back with a path that an independent re-check (the robot's URDF geometry against the object with
python-fcl, every segment at ten times the resolution of the object's pairs) finds free. The carried
test does the same with the object hanging from a palm, and shows once that the independent check
catches a planner whose model is blind to the carried object's obstacles.
"""
from __future__ import annotations

import itertools
import shutil
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from oracle import Oracle
from test_grasp_list import _crossings

from planner.motion.result import MotionParams
from planner.motion.space import JointSpace
from planner.motion.transit import TransitParams, shortcut

TRANSIT = TransitParams.of(MotionParams())
EXAMPLE = Path(__file__).resolve().parent.parent / "sessions" / "default-example"


def test_joint_space_holds_and_reduces():
    base = np.arange(6.0)
    space = JointSpace.of(np.full(6, -10.0), np.full(6, 10.0), np.array([1, 3]), base)
    q = space.full(np.array([[7.0, 8.0]]))[0]
    assert q.tolist() == [0.0, 7.0, 2.0, 8.0, 4.0, 5.0]
    assert space.holds(q) and not space.holds(q + 1)
    assert space.distance(base, q) == pytest.approx(np.hypot(6.0, 5.0))
    with pytest.raises(ValueError):
        space.base[0] = 1.0


def test_shortcuts_start_and_end_at_valid_states():
    """A point inside a checked segment need not be a valid state (between two checks it keeps the clearance, not the
    padding): a shortcut from it would not keep its guarantee. Here the path crosses a band of such points; no
    shortcut may start or end in it."""
    band = (0.3, 0.6)  # x range of states too near something to start a motion from
    wall = np.array([0.5, 0.9])  # a disc no motion may cross

    class Rule:
        def state_valid(self, q):
            return not band[0] < q[0] < band[1]

        def motion_valid(self, qa, qb, ends=True):
            if ends and not (self.state_valid(qa) and self.state_valid(qb)):
                return False
            s = np.clip(np.dot(wall - qa, qb - qa) / max(np.dot(qb - qa, qb - qa), 1e-12), 0.0, 1.0)
            return bool(np.linalg.norm(qa + s * (qb - qa) - wall) > 0.2)

    path = np.array([[0.0, 0.0], [0.2, 0.1], [0.8, 0.1], [1.0, 0.0], [1.0, 1.0]])
    rule = Rule()
    for seed in range(20):
        out = shortcut(path, rule, rule, np.random.default_rng(seed), 16)
        assert np.allclose(out[0], path[0]) and np.allclose(out[-1], path[-1])
        new = [q for q in out if not any(np.allclose(q, p) for p in path)]
        assert all(rule.state_valid(q) for q in new), f"seed {seed}: a shortcut starts or ends inside the band"
        assert all(rule.motion_valid(a, b, ends=False) for a, b in zip(out[:-1], out[1:]))


class Counting:
    """Every state and motion valid; the motions asked about recorded."""

    def __init__(self):
        self.calls = []

    def state_valid(self, q):
        return True

    def motion_valid(self, qa, qb, ends=True):
        self.calls.append((qa.copy(), qb.copy()))
        return True

    def lengths(self) -> list[float]:
        return [float(np.linalg.norm(b - a)) for a, b in self.calls]


def test_shortcuts_gaining_too_little_are_not_checked():
    """A straight path has nothing to gain: with a minimum gain no shortcut of it is checked. On an L-shaped one (legs of
    1) shortcuts are checked, the first (one leg to the other) saving at least the minimum, and the path gets shorter."""
    straight = np.array([[0.0, 0.0], [0.5, 0.0], [1.0, 0.0], [2.0, 0.0]])
    rule = Counting()
    out = shortcut(straight, rule, rule, np.random.default_rng(0), 16, min_gain=0.01)
    assert rule.calls == [] and np.array_equal(out, straight)
    corner = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    for seed in range(10):
        rule = Counting()
        path = shortcut(corner, rule, rule, np.random.default_rng(seed), 16, min_gain=0.1)
        assert rule.calls, f"seed {seed}: no shortcut of the corner was checked"
        a, b = rule.calls[0]  # the first: from the first leg (y = 0) to the second (x = 1), saving at least 0.1
        assert a[1] == 0.0 and b[0] == 1.0 and (1.0 - a[0]) + b[1] - np.linalg.norm(b - a) >= 0.1 - 1e-12
        assert np.linalg.norm(np.diff(path, axis=0), axis=1).sum() < 2.0


def test_vertex_shortcuts_jump_to_the_farthest_reachable_vertex_and_check_each_kept_motion_once():
    """A zigzag around a wall: the greedy pass jumps from each vertex to the farthest one a valid straight motion
    reaches; here that keeps as few vertices as a breadth-first search over all chains of valid jumps (the oracle, which
    shares no code). Every kept motion is valid and checked once, near the ends (from the first vertex, to the last) by
    the `near` validity. A nearly straight stretch is taken as it is, unchecked."""
    from planner.motion.transit import shortcut_vertices

    wall = (np.array([2.0, -1.0]), np.array([2.0, 0.5]))  # a segment no motion may cross

    def crosses(qa, qb):
        (p, r), d = wall, qb - qa
        den = d[0] * (r - p)[1] - d[1] * (r - p)[0]
        if abs(den) < 1e-12:
            return False
        t = ((p - qa)[0] * (r - p)[1] - (p - qa)[1] * (r - p)[0]) / den
        u = ((p - qa)[0] * d[1] - (p - qa)[1] * d[0]) / den
        return 0.0 <= t <= 1.0 and 0.0 <= u <= 1.0

    class Rule:
        def __init__(self):
            self.calls = []

        def state_valid(self, q):
            return True

        def motion_valid(self, qa, qb, ends=True):
            self.calls.append((tuple(qa), tuple(qb)))
            return not crosses(qa, qb)

    path = np.array([[0, 0], [1, -0.5], [1.5, 1], [2, 1.2], [2.5, 1], [3, -0.5], [4, 0], [5, 0.5], [6, 0]], dtype=float)
    full, near = Rule(), Rule()
    out = shortcut_vertices(path, full, near)
    # the oracle: fewest vertices over chains of valid jumps, breadth first
    n, best, frontier = len(path), {0: [0]}, [0]
    while n - 1 not in best:
        reached = []
        for i in frontier:
            for j in range(i + 1, n):
                if j not in best and not crosses(path[i], path[j]):
                    best[j] = best[i] + [j]
                    reached.append(j)
        frontier = reached
    assert len(out) == len(best[n - 1]) < len(path), (out, path[best[n - 1]])
    assert not any(crosses(a, b) for a, b in zip(out[:-1], out[1:]))
    kept = [(tuple(a), tuple(b)) for a, b in zip(out[:-1], out[1:])]
    calls = full.calls + near.calls
    assert all(calls.count(k) == 1 for k in kept), "each kept motion checked once"
    assert all(a == tuple(path[0]) or b == tuple(path[-1]) for a, b in near.calls)
    assert all(a != tuple(path[0]) and b != tuple(path[-1]) for a, b in full.calls)
    straight = np.array([[0.0, 0.0], [1.0, 0.01], [2.0, 0.0], [3.0, 0.01]])
    rule = Rule()
    assert np.array_equal(shortcut_vertices(straight, rule, rule, min_gain=0.1), straight) and rule.calls == []


def test_shortcuts_longer_than_the_limit_are_never_checked():
    """A graph path keeps its edges rather than try a long new motion: with `max_length`, no motion checked by either
    shortcut pass is longer than it (every motion valid here), the path's vertices stay where no short jump reaches,
    and without it the greedy pass jumps straight from the first vertex to the last."""
    from planner.motion.transit import shortcut_vertices

    zigzag = np.array([[0.0, 0.0], [0.6, 0.6], [1.2, 0.0], [1.8, 0.6], [2.4, 0.0], [3.0, 0.6]])
    rule = Counting()
    out = shortcut(shortcut_vertices(zigzag, rule, rule, 0.05, 1.0), rule, rule, np.random.default_rng(0), 50, 0.05, 1.0)
    assert rule.calls and max(rule.lengths()) <= 1.0
    assert np.linalg.norm(out[-1] - out[0]) > 1.0 and len(out) > 2
    rule = Counting()
    assert len(shortcut_vertices(zigzag, rule, rule, 0.05)) == 2 and max(rule.lengths()) > 3.0


def test_a_detour_made_online_is_cut_however_long():
    """The length limit keeps roadmap edges only: a jump that would replace part of a detour RRTConnect made (checked
    over every pair, as the jump would be) is tried whatever its length; the random pass keeps each piece's flag as it
    splices."""
    from planner.motion.transit import kept_detours, shortcut_vertices

    zigzag = np.array([[0.0, 0.0], [0.6, 0.6], [1.2, 0.0], [1.8, 0.6], [2.4, 0.0], [3.0, 0.6]])
    roadmap = np.zeros(5, dtype=bool)
    rule = Counting()
    assert len(shortcut_vertices(zigzag, rule, rule, 0.05, 1.0, roadmap)) == 6 and max(rule.lengths(), default=0.0) <= 1.0
    detour = roadmap.copy()
    detour[2] = True  # the middle segment came from a reconnection
    rule = Counting()
    out = shortcut_vertices(zigzag, rule, rule, 0.05, 1.0, detour)
    assert len(out) == 2 and max(rule.lengths()) > 3.0
    flags = kept_detours(zigzag, detour, zigzag[[0, 1, 2, 3, 5]])
    assert flags.tolist() == [False, False, True, False]  # the jump 3 -> 5 is new; the others are the path's own
    rule = Counting()
    shortcut(zigzag, rule, rule, np.random.default_rng(0), 200, 0.05, 1.0, detour)
    assert max(rule.lengths()) > 1.0  # some random shortcut over the detour is longer than the limit
    rule = Counting()
    shortcut(zigzag, rule, rule, np.random.default_rng(0), 200, 0.05, 1.0, roadmap)
    assert max(rule.lengths()) <= 1.0


def _phase_planner(scene, roadmap, baseline: bool = False):
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


@pytest.fixture(scope="module")
def example(tmp_path_factory):
    from planner.core.session import Session

    folder = tmp_path_factory.mktemp("motion") / "example"
    shutil.copytree(EXAMPLE, folder)
    s = Session.open(folder)
    return s.scene, s.result("roadmap"), s.result("pick_grasps")


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
    import pinocchio as pin
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
    import pinocchio as pin

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


def test_a_finger_whose_opening_would_hit_an_obstacle_opens_less(example):
    """Letting go at the example's placement with a small block put where one touching finger's tip goes when it opens
    by the release fraction: that finger opens less (or stays), the others open fully, and the opening motion found is
    free of the block by the independent check (the robot's URDF geometry through python-fcl, 50 samples)."""
    import dataclasses

    import pinocchio as pin

    from planner.collision.situation import Situation, fingertip_geometries
    from planner.core.session import Session
    from planner.model.environment import Obstacle
    from planner.motion.strategies import hand_grasp

    scene, roadmap, _ = example
    session = Session.open(EXAMPLE)
    dg, place = session.result("double_grasps"), session.result("place_grasps")
    b = hand_grasp(place, int(dg.place_rank[0]))
    robot, p = scene.robot, MotionParams()
    finger = b.touching[0]
    idx = robot.finger_idx[b.arm][finger]

    def tip(q):
        data = robot.model.createData()
        pin.framesForwardKinematics(robot.model, data, q)
        frame = robot.spec.arm(b.arm).hand.prefixed(next(f.tip_frame for f in robot.spec.arm(b.arm).hand.fingers if f.name == finger))
        return data.oMf[robot.frame_id(frame)].translation.copy()

    q = dg.q_place[0]
    opened = _phase_planner(scene, roadmap).hand.opened(b, p.release, True)
    reached = q.copy()
    reached[robot.hand_idx[b.arm]] = opened
    block = np.eye(4)
    block[:3, 3] = tip(reached)
    blocked = dataclasses.replace(scene, environment=scene.environment + (Obstacle("block", "box", (0.015, 0.015, 0.015), block),))
    planner = _phase_planner(blocked, roadmap)
    situation = Situation(None, scene.object_final, fingertip_geometries(planner.validities.cm, b.arm, b.touching))
    values = planner.contact.letting_go(b, q, situation)
    hand = robot.hand_idx[b.arm]
    at = np.isin(hand, idx)
    assert not np.allclose(values[at], opened[at]), "the blocked finger opened into the block"
    assert np.allclose(values[~at], opened[~at]), "the other fingers did not open by the release fraction"
    oracle = Oracle(blocked)
    end = q.copy()
    end[hand] = values
    for s in np.linspace(0.0, 1.0, 50):
        hits = [h for h in oracle.collisions(q + s * (end - q), scene.object_final, None, b.arm, False) if "block" in h]
        assert not hits, f"the opening finger hits the block at s={s:.2f}: {hits}"


def test_finger_motions_move_joint_by_joint_from_the_tip_and_from_the_base(example):
    """The ways a hand's fingers close: all joints at once first; among the others, one moving every finger's joints one
    depth at a time from the tip to the base and one from the base to the tip (a finger curling onto a rounded surface
    hooks its tip first); every way starts at q and ends at the target, and no two are the same."""
    from planner.motion.validities import Checked

    scene, roadmap, _ = example
    robot = scene.robot
    planner = _phase_planner(scene, roadmap)
    arm = robot.spec.arm_names[0]
    hand, fingers = robot.hand_idx[arm], list(robot.finger_idx[arm].values())
    q = robot.q_rest.copy()
    target = robot.lower[hand] + 0.5 * (robot.upper[hand] - robot.lower[hand])
    paths = planner.hand.motions(q, arm, target)
    assert len(paths[0]) == 2, "the first way is not all joints at once"
    for path in paths:
        assert np.allclose(path[0], q) and np.allclose(path[-1, hand], target)
        assert np.allclose(np.delete(path, hand, axis=1), np.delete(q, hand)), "a joint outside the hand moved"
    assert len({path.round(9).tobytes() for path in paths}) == len(paths), "the same way offered twice"
    depth = max(len(idx) for idx in fingers)

    def moved_depths(path):
        """Per step of a path, the depths (0: a finger's last joint) of the hand joints it moves."""
        out = []
        for a, b in zip(path[:-1], path[1:]):
            out.append({len(idx) - 1 - k for idx in fingers for k, j in enumerate(idx) if not np.isclose(a[j], b[j])})
        return out

    orders = [moved_depths(path) for path in paths]
    assert [{d} for d in range(depth)] in orders, "no way closes one joint depth at a time from the tip"
    assert [{d} for d in reversed(range(depth))] in orders, "no way closes one joint depth at a time from the base"
    assert planner.hand.motions(q, arm, q[hand]) == [], "fingers already there moved"

    # a hand where one finger must close from the tip to the base while another must close all at once: no hand-wide
    # order fits both, the fingers one after the other do
    names = list(robot.finger_idx[arm])
    hook, whole = robot.finger_idx[arm][names[0]], robot.finger_idx[arm][names[1]]

    class Rule:
        """Valid: `hook` moves one joint at a time, tip before base; `whole` moves all its joints at once (a path that
        breaks the rule fails at its first configuration)."""

        def path_hit(self, path):
            return None if self.follows(path) else path[0]

        def follows(self, path):
            steps = list(zip(path[:-1], path[1:]))
            if any(np.sum(~np.isclose(a[hook], b[hook])) > 1 for a, b in steps):
                return False
            if sum(not np.allclose(a[whole], b[whole]) for a, b in steps) > 1:
                return False
            order = [min(k for k in range(len(path) - 1) if not np.isclose(path[k, j], path[k + 1, j])) for j in hook
                     if not np.isclose(path[0, j], path[-1, j])]
            return order == sorted(order, reverse=True)

    found = planner.hand.path(q, arm, target, Checked(Rule()))
    assert found is not None and Rule().follows(found), "no valid way found finger by finger"
    assert np.allclose(found[0], q) and np.allclose(found[-1, hand], target)


def test_paddings_fitted_pair_by_pair():
    """A transit end near something lowers the padding of the pairs it holds close only: those found are exactly the
    pairs an exhaustive distance query puts near enough, each padded to leave 90 % of its margin over the clearance; a
    pair padded otherwise changes the spacing only of the segments that move it relative to its partner."""
    import pinocchio as pin

    from planner.collision.checker import build_collision_model
    from planner.collision.validity import Clearances, far, make_validity, transit_profile
    from planner.model.task import find_task, load_task

    scene = load_task(find_task("default"))
    robot = scene.robot
    cm = build_collision_model(robot, scene.environment)
    profile = transit_profile({"env_clearance_m": 0.01, "self_clearance_m": 0.004}, 0.03, 0.015)
    q = scene.q_initial
    meter = Clearances(cm, "all", far(profile))
    near = meter(q)
    lowered = dict(meter.fitted_pairs(profile, near))

    # the oracle: every pair's distance from a fresh geometry data, no security margin, no broad phase
    gm, data = cm.geometry, robot.model.createData()
    gd = pin.GeometryData(gm)
    pin.updateGeometryPlacements(robot.model, data, gm, gd, q)
    env = set(cm.subsets["env"].tolist())
    expected = {}
    for k in range(len(gm.collisionPairs)):
        d = pin.computeDistance(gm, gd, k).min_distance
        padding, keep = (profile.env_padding, profile.env_clearance) if k in env else (profile.self_padding, profile.self_clearance)
        if keep < 0.9 * d and keep + 0.9 * (d - keep) < padding:
            expected[k] = keep + 0.9 * (d - keep)  # 90 % of the end's margin over the clearance left between checks
    assert expected, "the test needs a pair near enough at q_initial to be fitted"
    assert set(lowered) == set(expected)
    assert all(abs(lowered[k] - expected[k]) < 1e-6 for k in expected)

    # one of them padded a tenth of a millimetre above its clearance: only the segments that move it get denser
    k = next(iter(lowered))
    keep = profile.env_clearance if k in env else profile.self_clearance
    plain = make_validity(cm, profile, "all")
    tight = make_validity(cm, profile, "all", pair_padding=((k, keep + 1e-4),))
    moves = cm.relative_joints()[k]
    for j in range(robot.nq):
        qb = q.copy()
        qb[j] = q[j] + (0.3 if q[j] + 0.3 <= robot.upper[j] else -0.3)
        if moves[j]:
            assert tight.samples(q, qb) > plain.samples(q, qb), f"joint {j} moves the tight pair: denser"
        else:
            assert tight.samples(q, qb) == plain.samples(q, qb), f"joint {j} does not move it: as sparse as the plain profile"
    assert moves.any() and not moves.all(), "the segments must include both cases"


def test_clearances_measure_exactly_the_pairs_nearer_than_far():
    """The clearance meter (the broad phase with `far` as margins, then exact distances) measures exactly the pairs that
    an exhaustive distance query puts nearer than `far` of their kind, at their distances: random configurations around
    the rest pose, the statuette static on the desk and screened by its hull."""
    import pinocchio as pin

    from planner.collision.checker import build_collision_model
    from planner.collision.shapes import coal_convex, coal_mesh
    from planner.collision.situation import Situation, situation_model
    from planner.collision.validity import Clearances, far, transit_profile
    from planner.model.task import find_task, load_task

    scene = load_task(find_task("default"))
    robot = scene.robot
    mesh = scene.object_mesh
    model = situation_model(build_collision_model(robot, scene.environment), coal_mesh(mesh), Situation(None, scene.object_initial),
                            (), np.arange(robot.nq), coal_convex(mesh.convex_hull))
    limits = far(transit_profile({"env_clearance_m": 0.01, "self_clearance_m": 0.0}, 0.03, 0.015))
    meter = Clearances(model, "moving", limits)
    gm, data = model.geometry, robot.model.createData()
    gd = pin.GeometryData(gm)  # the oracle: every pair's distance from a fresh geometry data, no margin, no broad phase
    kind = {int(k): "env" for k in model.subsets["env"]} | {int(k): "object" for k in model.subsets["object"]}
    rng = np.random.default_rng(5)
    measured = 0
    for _ in range(30):
        q = np.clip(robot.q_rest + rng.normal(0.0, 0.4, robot.nq), robot.lower, robot.upper)
        near = meter(q)
        pin.updateGeometryPlacements(robot.model, data, gm, gd, q)
        exact = {int(k): pin.computeDistance(gm, gd, int(k)).min_distance for k in model.subsets["moving"]}
        expected = {k for k, d in exact.items() if d < limits[kind.get(k, "self")]}
        borderline = {k for k, d in exact.items() if abs(d - limits[kind.get(k, "self")]) < 1e-6}
        assert set(near) ^ expected <= borderline, sorted(set(near) ^ expected)
        assert all(abs(near[k] - exact[k]) < 1e-6 for k in near)
        measured += len(near)
    assert measured > 100, "the configurations must bring many pairs near"


def test_the_clearance_meter_measures_a_configuration_the_same_whatever_it_measured_before(example, monkeypatch):
    """Along the example's motion (hands near the vase, the object carried), a configuration measured again after five
    others gives the very same distances: what a fitted padding, and so the checks it spaces, is made of depends only on
    the configuration (pinocchio's per-pair distance functors kept their GJK state and moved by up to 5e-7 m). The
    checker keeps one configuration's distances only, so each is measured again."""
    from planner.collision import checker as checker_module
    from planner.collision.checker import build_collision_model
    from planner.collision.situation import Situation
    from planner.collision.validity import transit_profile
    from planner.core.session import Session
    from planner.motion.result import MotionParams
    from planner.motion.step import contact_profile
    from planner.motion.transit_stage import transit_joints
    from planner.motion.validities import Validities

    monkeypatch.setattr(checker_module, "MEASURED", 1)
    scene, roadmap, _ = example
    m = Session.open(EXAMPLE).result("motion")
    robot, p = scene.robot, MotionParams()
    validities = Validities(scene, build_collision_model(robot, scene.environment),
                            transit_profile(roadmap.resolution, p.transit_env_padding, p.transit_self_padding), contact_profile(p))
    rng = np.random.default_rng(0)
    measured = 0
    for k in rng.choice(len(m.q), 40, replace=False):
        q, arm = m.q[k], robot.spec.arm_names[m.holder[k]] if m.holder[k] >= 0 else None
        hold = m.object_pose[k] if arm is None else np.linalg.inv(robot.frame_placement(q, robot.palm_frame(arm))) @ m.object_pose[k]
        checks = validities.of(Situation(arm, hold), q, transit_joints(robot))
        first = checks.meter(q)
        for j in rng.choice(len(m.q), 5):
            checks.meter(m.q[j])
        assert checks.meter(q) == first, k
        measured += len(first)
    assert measured > 50, "the samples must bring many pairs near"


def test_meters_of_one_situation_measure_each_pair_once_per_configuration(example, monkeypatch):
    """The clearance meters of one situation's motions (other moving joints, other pairs) share what their checker
    measured: along the example's motion, a meter of the arms alone after one of the torso and arms measures no pair
    again, and both give the distances a meter on a checker of its own gives (the oracle: nothing shared)."""
    from planner.collision.checker import CollisionChecker, build_collision_model
    from planner.collision.situation import Situation
    from planner.collision.validity import Clearances, far, transit_profile
    from planner.core.session import Session
    from planner.motion.result import MotionParams
    from planner.motion.step import contact_profile
    from planner.motion.transit_stage import transit_joints
    from planner.motion.validities import Validities

    scene, roadmap, _ = example
    m = Session.open(EXAMPLE).result("motion")
    robot, p = scene.robot, MotionParams()
    profile = transit_profile(roadmap.resolution, p.transit_env_padding, p.transit_self_padding)
    validities = Validities(scene, build_collision_model(robot, scene.environment), profile, contact_profile(p))
    arms = np.concatenate([robot.arm_idx[a] for a in robot.spec.arm_names])
    made = []
    monkeypatch.setattr(CollisionChecker, "distance", lambda self, pair, real=CollisionChecker.distance: made.append(pair)
                        or real(self, pair))
    rng = np.random.default_rng(1)
    shared = 0
    for k in rng.choice(len(m.q), 30, replace=False):
        q, arm = m.q[k], robot.spec.arm_names[m.holder[k]] if m.holder[k] >= 0 else None
        hold = m.object_pose[k] if arm is None else np.linalg.inv(robot.frame_placement(q, robot.palm_frame(arm))) @ m.object_pose[k]
        whole, alone = (validities.of(Situation(arm, hold), q, idx) for idx in (transit_joints(robot), arms))
        assert whole.checker is alone.checker
        first = whole.meter(q)
        before = len(made)
        second = alone.meter(q)
        assert set(made[before:]) <= set(alone.model.subsets["moving"]) - set(whole.model.subsets["moving"]), k
        for near, cm in ((first, whole.model), (second, alone.model)):
            fresh = Clearances(cm, "moving", far(profile), CollisionChecker(cm))(q)
            assert near == fresh, k
        shared += len(set(first) & set(second))
    assert shared > 50, "the samples must bring pairs both meters measure near"


@pytest.mark.parametrize("baseline", [False, True], ids=["roadmap", "rrt"])
def test_transit_checks_and_pair_tests_count_every_check_of_the_transit(example, monkeypatch, baseline):
    """Table I's transit checks are every collision check a transit makes, counted apart from the planner's own tally:
    each call of the collision checker while the transit runs; its pair tests, pinocchio's count of the pairs each
    check's broad phase passed to the exact test, and each pair tested alone (a screened mesh), those of RRTConnect and
    of the shortcuts apart. The example's Rest transit, from where the placing hand retreated (near the object: some
    pairs checked densely) to the final configuration."""
    from collections import Counter

    import planner.motion.transit as transit_module
    import planner.motion.transit_stage as stage_module
    from planner.collision.checker import CollisionChecker
    from planner.collision.situation import Situation
    from planner.core.session import Session
    from planner.motion.phase import Phase
    from planner.motion.result import PHASES

    scene, roadmap, _ = example
    robot = scene.robot
    motion = Session.open(EXAMPLE).result("motion")
    rest = np.flatnonzero(motion.phase == PHASES.index("Rest"))
    start = motion.q[rest[0] - 1]  # the placing hand a few centimetres from the object
    hands = np.concatenate(list(robot.hand_idx.values()))
    goal = scene.q_final.copy()
    goal[hands] = start[hands]
    planner = _phase_planner(scene, roadmap, baseline)
    calls, tested = [], []
    check = CollisionChecker.in_collision
    monkeypatch.setattr(CollisionChecker, "in_collision", lambda self, *a, **k: calls.append(1) or check(self, *a, **k))
    collide = pin.computeCollisions

    part, by_part = ["graph"], Counter()

    def counted(*args):  # pinocchio's own count of the pairs its callback sent to the exact test
        hit = collide(*args)
        n = sum(a.count for a in args if isinstance(a, pin.CollisionCallBackDefault))
        tested.append(n)
        by_part[part[-1]] += n
        return hit

    def one(*args):  # one pair, tested exactly
        tested.append(1)
        by_part[part[-1]] += 1
        return alone(*args)

    def labelled(module, name: str, label: str) -> None:
        function = getattr(module, name)

        def run(*args, **kwargs):
            part.append(label)
            try:
                return function(*args, **kwargs)
            finally:
                part.pop()

        monkeypatch.setattr(module, name, run)

    monkeypatch.setattr(pin, "computeCollisions", counted)
    alone = pin.computeCollision
    monkeypatch.setattr(pin, "computeCollision", one)
    labelled(transit_module, "_rrt", "rrt")
    for name in ("shortcut_vertices", "shortcut"):
        labelled(stage_module, name, "shortcut")
    planner.stage(Phase.REST).transit(start, goal, Situation(None, scene.object_final))
    stats = planner.stats[Phase.REST]
    assert stats.checks == len(calls) > 2, (stats.checks, len(calls))
    assert stats.pair_tests == sum(tested) >= len(calls) / 2, (stats.pair_tests, sum(tested))
    assert (stats.pairs_rrt, stats.pairs_shortcut) == (by_part["rrt"], by_part["shortcut"]), by_part
    assert by_part["shortcut"] > 0 and (by_part["rrt"] > 0) == baseline  # ours' Rest follows the graph, no reconnection
    assert stats.pairs_away == 0
    # an arm moved alone (both planners by RRTConnect): counted whole, apart, in neither RRTConnect's part nor the
    # shortcuts'
    arm, idx = robot.spec.arm_names[0], robot.arm_idx[robot.spec.arm_names[0]]
    target = start.copy()
    target[idx] += 0.2 * (scene.q_final[idx] - start[idx])  # a fifth of the way to its final values: free
    before = (stats.pairs_rrt, stats.pairs_shortcut, stats.pair_tests, sum(tested))
    planner.stage(Phase.REST).transit(start, target, Situation(None, scene.object_final), arm)
    assert (stats.pairs_rrt, stats.pairs_shortcut) == before[:2]
    assert stats.pairs_away == stats.pair_tests - before[2] == sum(tested) - before[3] > 0


def test_an_arm_moved_alone_has_its_own_budget(example, monkeypatch):
    """The picking arm's move away is RRTConnect with `away_motions` motion checks, for either planner (found within a
    few hundred or not at all: docs/benchmarks.md), not the reconnections' nor the baseline's query budget."""
    import dataclasses

    import planner.motion.transit as transit_module
    from planner.collision.situation import Situation
    from planner.core.session import Session
    from planner.motion.phase import Phase
    from planner.motion.result import PHASES

    scene, roadmap, _ = example
    robot = scene.robot
    motion = Session.open(EXAMPLE).result("motion")
    start = motion.q[np.flatnonzero(motion.phase == PHASES.index("Rest"))[0] - 1]
    idx = robot.arm_idx[robot.spec.arm_names[0]]
    target = start.copy()
    target[idx] += 0.2 * (scene.q_final[idx] - start[idx])
    budgets = []
    real = transit_module._rrt
    monkeypatch.setattr(transit_module, "_rrt", lambda *a: budgets.append(a[5]) or real(*a))
    for baseline in (False, True):
        planner = _phase_planner(scene, roadmap, baseline)
        planner.p = dataclasses.replace(planner.p, away_motions=37)
        planner.stage(Phase.REST).transit(start, target, Situation(None, scene.object_final), robot.spec.arm_names[0])
    assert budgets == [37, 37]


def test_the_carry_transit_can_use_the_roadmap_nodes(example):
    """While a hand holds the object, its closed fingers stay near its own wrist (nearer than the transit padding): the
    validity of the whole Carry transit pads those pairs as its two ends allow, so roadmap nodes near its start are
    valid there (with those pairs at the transit padding, none was, and the graph went unused). The example's Carry
    transit: the samples of phase Carry where no hand works at the object, the picking arm holding it."""
    from planner.collision.situation import Situation
    from planner.core.session import Session
    from planner.motion.result import PHASES
    from planner.motion.space import JointSpace

    scene, roadmap, _ = example
    robot = scene.robot
    motion = Session.open(EXAMPLE).result("motion")
    carry = np.flatnonzero((motion.phase == PHASES.index("Carry")) & (motion.active == -1) & (motion.holder >= 0))
    run = np.split(carry, np.flatnonzero(np.diff(carry) > 1) + 1)[0]  # the first stretch: the transit
    q_start, q_goal = motion.q[run[0]], motion.q[run[-1]]
    arm = motion.arms[int(motion.holder[run[0]])]
    planner = _phase_planner(scene, roadmap)
    hold = np.linalg.inv(motion.object_pose[run[0]]) @ planner.arms.palm(q_start, arm)
    full, _ = planner.validities.of(Situation(arm, hold), q_start, planner.contact.transit_idx).transit_validities(q_start, q_goal)
    space = JointSpace.of(robot.lower, robot.upper, planner.contact.transit_idx, q_start)
    nearest = np.argsort(space.distance(roadmap.node_q, q_start), kind="stable")[:48]
    valid = sum(full.on("changed").state_valid(space.full(space.reduce(roadmap.node_q[n]))) for n in nearest)
    assert valid >= 12, f"only {valid} of the 48 roadmap nodes nearest the Carry start are valid while it holds the object"


@pytest.mark.slow
def test_graded_checks_densely_only_beside_a_tight_end(example):
    """The robot at its initial configuration, the statuette standing 3 mm beside its first arm's palm (moved out from it
    sideways, away from the other palm, by bisection): motions out of there checked graded cost a
    fraction of the checks at paddings fitted to the 3 mm throughout, and each one it passes keeps the hand off the
    statuette, and the robot off itself and the obstacles, by the independent check at ten times the fitted resolution.
    Its paddings must be ordered."""
    from planner.collision.situation import Situation
    from planner.collision.validity import Graded
    from planner.collision.with_object import OBJECT

    scene, roadmap, _ = example
    planner = _phase_planner(scene, roadmap)
    idx = planner.contact.transit_idx
    q = scene.q_initial.copy()
    first, other = scene.robot.spec.arm_names[:2]
    palm = planner.arms.palm(q, first)[:3, 3]
    out = palm - planner.arms.palm(q, other)[:3, 3]
    out[2] = 0.0
    out /= np.linalg.norm(out)
    rotation, centre = scene.object_initial[:3, :3], np.asarray(scene.object_mesh.centroid)

    def beside(distance):
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = rotation, palm + distance * out - rotation @ centre
        situation = Situation(None, pose)
        checks = planner.validities.of(situation, q, idx)
        model = checks.model
        obj = [o.name for o in model.geometry.geometryObjects].index(OBJECT)
        gaps = [d for k, d in checks.clearances(q).items() if obj in model.ends[k]]
        return situation, checks, min(gaps, default=np.inf)

    low, high = 0.0, 0.5  # the statuette's centre this far out from the palm: nearer than 3 mm at low, not at high
    for _ in range(20):
        mid = (low + high) / 2
        low, high = (mid, high) if beside(mid)[2] < 0.003 else (low, mid)
    situation, checks, gap = beside(high)
    assert 0.0025 < gap < 0.0035, gap
    goal = q.copy()
    goal[idx] = scene.robot.q_rest[idx]
    full, near = checks.transit_validities(q, goal)
    graded = Graded(full, near)
    with pytest.raises(ValueError, match="coarse paddings must be at least"):
        Graded(near, full)
    rng = np.random.default_rng(3)
    moved = np.isin(np.arange(len(q)), idx)
    ends = [e for e in (q + moved * rng.normal(0.0, 0.3, len(q)) for _ in range(40)) if full.state_valid(e)][:6]
    oracle = Oracle(scene)
    spent = {"graded": 0, "fitted": 0}
    passed = 0
    for end in ends:  # RRT-like steps out of the tight spot
        ok = {}
        for name, validity in (("graded", graded), ("fitted", near)):
            before = validity.checks
            ok[name] = validity.motion_valid(q, end, ends=False)
            spent[name] += validity.checks - before
        if ok["graded"]:
            passed += 1
            for s in np.linspace(0.0, 1.0, 10 * near.samples(q, end, "object")):  # the pairs fitted to the 3 mm
                assert not oracle.object_hits(q + s * (end - q), situation.pose)
                assert not oracle.robot_collisions(q + s * (end - q))  # the others, tested only at the coarse spacing
    assert passed, "some motions must pass"
    assert spent["graded"] < 0.5 * spent["fitted"], spent


@pytest.mark.slow
def test_the_hull_screen_changes_no_answer(example):
    """A situation model whose object pairs are screened by the object's convex hull answers every check as the same
    model without the screen: along the example's Carry (the object held), and with the statuette standing where a
    fingertip of the Carry's first configuration lies in a pocket of its hull, centimetres from the statuette itself
    (pockets found by sampling the hull; the fingers then moved at random), so that some configurations hit the hull
    and not the statuette (counted with a model whose object is the hull itself); there, a pair padded by 10 m is found
    colliding past the hull."""
    import coal
    import pinocchio as pin

    from planner.collision.checker import build_collision_model
    from planner.collision.shapes import coal_convex, coal_mesh
    from planner.collision.situation import Situation, situation_model
    from planner.collision.validity import make_validity, transit_profile
    from planner.core.session import Session
    from planner.motion.result import PHASES

    scene, roadmap, _ = example
    robot = scene.robot
    motion = Session.open(EXAMPLE).result("motion")
    carry = np.flatnonzero(motion.phase == PHASES.index("Carry"))
    arm = robot.spec.arm_names[motion.holder[carry[0]]]
    planner = _phase_planner(scene, roadmap)
    cm = build_collision_model(robot, scene.environment)
    idx = planner.contact.transit_idx
    profile = transit_profile(roadmap.resolution, 0.02, 0.008)
    hull: coal.CollisionGeometry = coal_convex(scene.object_mesh.convex_hull)
    mesh = coal_mesh(scene.object_mesh)

    def models(situation):
        return [make_validity(situation_model(cm, shape, situation, (), idx, screen), profile, "moving")
                for shape, screen in ((mesh, hull), (mesh, None), (hull, None))]

    def hull_only(situation, configurations) -> int:
        screened, plain, as_hull = models(situation)
        assert screened.seg.cm.twins is not None and plain.seg.cm.twins is None
        count = 0
        for q in configurations:
            for subset in ("moving", "changed", "object"):
                answer = plain.on(subset).state_valid(q)
                assert screened.on(subset).state_valid(q) == answer, f"subset {subset}"
                if answer and not as_hull.on(subset).state_valid(q):
                    count += 1
                    past_hull.append(padded_pairs_collide(screened.seg.cm, q, subset))
            assert screened.colliding_pairs(q) == plain.colliding_pairs(q)
        return count

    def padded_pairs_collide(model, q, subset: str) -> int:
        """At a configuration where a hull is hit and its mesh is free, each pair of the robot and the obstacles the
        naive broad phase meets after that hull, padded by 10 m in a subset of the two, collides: how many checks found
        it past the hull (whose mesh pair then takes its place, `_demote`)."""
        from planner.collision.checker import CollisionChecker
        from planner.collision.pair_tables import pair_table

        def spied():
            checker, demoted = CollisionChecker(model), []
            demote = checker._demote
            checker._demote = lambda *args: (demoted.append(args[1]), demote(*args))
            return checker, demoted

        checker, hull_hit = spied()
        assert not checker.in_collision(q, subset) and hull_hit
        k = hull_hit[0]
        twin = int(model.twins[k])
        held = np.union1d(model.ends[k], model.ends[twin])  # the object's mesh and hull
        others = np.flatnonzero(~np.isin(model.ends, held).any(axis=1))
        later = others[model.ends[others, 0] > model.ends[k, 0]]  # the naive broad phase's order
        paddings, past = model.paddings(), 0
        for j in later[:: max(1, len(later) // 20)]:
            checker, demoted = spied()
            padded = paddings.copy()
            padded[j] = 10.0
            assert checker.in_collision(q, np.array([min(twin, j), max(twin, j)]), margins=pair_table(model, padded)), \
                f"pair {j}, padded by 10 m"
            past += bool(demoted)
        return past

    past_hull: list[int] = []

    q = motion.q[carry[0]]
    hold = np.linalg.inv(motion.object_pose[carry[0]]) @ planner.arms.palm(q, arm)
    found = hull_only(Situation(arm, hold), motion.q[carry[::2]])
    rng = np.random.default_rng(0)
    fingers = np.concatenate(list(robot.hand_idx.values()))
    moved = [q]
    for _ in range(12):
        moved.append(q.copy())
        moved[-1][fingers] = rng.uniform(robot.lower[fingers], robot.upper[fingers])
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    tips = [data.oMf[robot.frame_id(robot.spec.arm(a).hand.prefixed(f.tip_frame))].translation
            for a in robot.spec.arm_names for f in robot.spec.arm(a).hand.fingers]
    rotation = scene.object_initial[:3, :3]
    for pocket, tip in itertools.product(_hull_pockets(scene.object_mesh, 0.03, rng)[:3], tips):
        if found:
            break
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = rotation, tip - rotation @ pocket
        found += hull_only(Situation(None, pose), moved)
    assert found, "some configurations must hit the hull and not the statuette"
    assert sum(past_hull) > 0, "some padded pairs must be found past a hull hit whose mesh is free"


def _hull_pockets(mesh, clearance: float, rng: np.random.Generator) -> np.ndarray:
    """Points inside a mesh's convex hull, outside the mesh (odd crossings of a ray) and at least `clearance` from its
    surface (by 100,000 points sampled on it), the farthest first."""
    import trimesh
    from scipy.spatial import cKDTree

    hull = mesh.convex_hull
    points = rng.uniform(hull.bounds[0], hull.bounds[1], (4000, 3))
    inside_hull = np.all(np.einsum("fi,pi->pf", hull.face_normals, points)
                         < np.einsum("fi,fi->f", hull.face_normals, hull.triangles[:, 0]), axis=1)
    surface, _ = trimesh.sample.sample_surface(mesh, 100_000, seed=1)
    gap = cKDTree(surface).query(points)[0]
    keep = np.flatnonzero(inside_hull & (gap > clearance + 0.002))  # the sampled points lie about a millimetre apart
    keep = [k for k in keep if _crossings(points[k], np.array([0.36, 0.48, 0.8]), mesh.triangles) % 2 == 0]
    return points[sorted(keep, key=lambda k: -gap[k])]


def test_situations_made_alike_share_one_collision_model(example):
    """Each candidate lift makes its own Situation: alike ones (holder, pose, touching, support) share one model and
    one collision data, each of which costs milliseconds to make; a fingertip allowed to touch makes another, without
    that fingertip's pairs with the object, and the shared checker answers as a checker of its own does."""
    from planner.collision.checker import CollisionChecker
    from planner.collision.situation import Situation, fingertip_geometries
    from planner.motion.transit_stage import transit_joints

    scene, roadmap, _ = example
    robot = scene.robot
    validities = _phase_planner(scene, roadmap).validities
    q, idx = scene.q_initial, transit_joints(robot)
    first = validities.of(Situation(None, scene.object_initial), q, idx)
    again = validities.of(Situation(None, scene.object_initial.copy()), q, idx)
    assert again is first and again.checker is first.checker
    finger = robot.spec.arm("right").hand.fingers[0].name
    tips = fingertip_geometries(validities.cm, "right", [finger])
    touching = validities.of(Situation(None, scene.object_initial, tips), q, idx)
    assert touching.checker is not first.checker and touching.model.geometry is not first.model.geometry

    def names(model, subset):
        objs, pairs = model.geometry.geometryObjects, model.geometry.collisionPairs
        return {(objs[pairs[int(k)].first].name, objs[pairs[int(k)].second].name) for k in model.subsets[subset]}

    assert not any(tip in pair for tip in tips for pair in names(touching.model, "object"))
    assert any(tip in pair for tip in tips for pair in names(first.model, "object"))
    rng = np.random.default_rng(3)
    own = CollisionChecker(first.model)
    for _ in range(30):
        x = robot.clip(q + rng.normal(0.0, 0.4, robot.nq))
        assert first.checker.in_collision(x, "moving") == own.in_collision(x, "moving")
