"""The simplified collision model against the full meshes, the pruned pairs, and the subsets."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from sandbox import forbid

from planner.collision.checker import simplified_robot_geometry
from planner.collision.pairs import CollisionParams, _candidate_pairs, compute_pair_set, robot_pair_set
from planner.handover.reach import reach
from planner.model.geometry import se3


def _full_mesh_model(scene, cm):
    """The original URDF collision meshes + the obstacles, with every pair the simplified model may skip
    only for a stated reason (adjacent links, touching at rest) removed."""
    robot = scene.robot
    gm = robot.collision_model.copy()
    n_robot = len(gm.geometryObjects)
    pairs, _, _ = _candidate_pairs(robot, gm)
    names = [o.name for o in gm.geometryObjects]
    data, gd = robot.model.createData(), None
    gm.removeAllCollisionPairs()
    for i, j in pairs:
        gm.addCollisionPair(pin.CollisionPair(i, j))
    gd = pin.GeometryData(gm)
    pin.computeCollisions(robot.model, data, gm, gd, robot.q_rest, False)
    at_rest = {(names[cp.first], names[cp.second]) for cp, r in zip(gm.collisionPairs, gd.collisionResults) if r.isCollision()}
    gm.removeAllCollisionPairs()
    for i, j in pairs:
        if (names[i], names[j]) not in at_rest:
            gm.addCollisionPair(pin.CollisionPair(i, j))
    for ob in scene.environment:
        gm.addGeometryObject(pin.GeometryObject(f"env/{ob.name}", 0, 0, se3(ob.pose), ob.coal_shape()))
    for i in range(n_robot):
        if gm.geometryObjects[i].parentJoint != 0:
            for e in range(n_robot, len(gm.geometryObjects)):
                gm.addCollisionPair(pin.CollisionPair(i, e))
    return gm, at_rest


@pytest.mark.slow
def test_no_collision_missed_against_full_meshes(default_scene, default_collision):
    """On 1,000 configurations around rest, every full-mesh collision is also found by the hull model."""
    robot = default_scene.robot
    gm, _ = _full_mesh_model(default_scene, default_collision)
    data, gd = robot.model.createData(), pin.GeometryData(gm)
    checker = default_collision.checker()
    rng = np.random.default_rng(7)
    mesh_hits = hull_hits = 0
    for _ in range(1000):
        q = robot.clip(robot.q_rest + rng.normal(0.0, 0.6, robot.nq))
        mesh = pin.computeCollisions(robot.model, data, gm, gd, q, True)
        hull = checker.in_collision(q)
        assert hull or not mesh, "a full-mesh collision was missed by the simplified model"
        mesh_hits += mesh
        hull_hits += hull
    assert 100 < mesh_hits < 900, "the sample should mix free and colliding configurations"
    # Hulls are conservative but not absurdly so: most hull-only hits must also be mesh hits.
    assert hull_hits - mesh_hits < 0.5 * (1000 - mesh_hits)


def test_pruned_pairs_never_collide_on_fresh_samples(default_scene, default_collision):
    """The pairs pruned by sampling collide in none of 3,000 fresh uniform samples (other seed)."""
    robot = default_scene.robot
    gm = simplified_robot_geometry(robot)
    pairs, _, _ = _candidate_pairs(robot, gm)
    names = [o.name for o in gm.geometryObjects]
    kept = set(default_collision.pair_set.kept)
    gm.removeAllCollisionPairs()
    for i, j in pairs:
        if (names[i], names[j]) not in kept:
            gm.addCollisionPair(pin.CollisionPair(i, j))
    data, gd = robot.model.createData(), pin.GeometryData(gm)
    pin.computeCollisions(robot.model, data, gm, gd, robot.q_rest, False)
    for k, r in enumerate(gd.collisionResults):
        if r.isCollision():  # disabled because touching at rest, by design
            gd.deactivateCollisionPair(k)
    active = sum(gd.activeCollisionPairs)
    assert active == default_collision.pair_set.pruned
    rng = np.random.default_rng(12345)
    for _ in range(3000):
        assert not pin.computeCollisions(robot.model, data, gm, gd, rng.uniform(robot.lower, robot.upper), True)


def test_pair_set_is_deterministic_and_cached(default_scene, tmp_path, monkeypatch):
    robot = default_scene.robot
    params = CollisionParams(prune_samples=300)
    gm = simplified_robot_geometry(robot)
    a = compute_pair_set(robot, gm, params)
    b = compute_pair_set(robot, gm, params)
    assert a == b
    monkeypatch.setenv("REGRASP_CACHE", str(tmp_path))
    c = robot_pair_set(robot, gm, params)
    assert list(tmp_path.rglob("*.json")), "the pair set was not cached"
    forbid(monkeypatch, "planner.collision.pairs.compute_pair_set")
    assert robot_pair_set(robot, gm, params) == c == a


def test_subsets(default_scene, default_collision):
    """Both hands brought to one point collide as 'hands' but not with the environment."""
    robot = default_scene.robot
    checker = default_collision.checker()
    assert not checker.in_collision(default_scene.q_initial)
    rng = np.random.default_rng(0)
    target = np.array([0.40, 0.0, 1.05])
    right = reach(robot, checker, "right", target, rng)
    left = reach(robot, checker, "left", target + [0.0, 0.0, 0.02], rng)
    assert right.reachable and left.reachable
    q = right.q.copy()
    q[robot.arm_idx["left"]] = left.q[robot.arm_idx["left"]]
    q[robot.torso_idx] = right.q[robot.torso_idx]
    assert checker.in_collision(q, "hands")
    assert checker.in_collision(q)
    assert not checker.in_collision(q, "right_env")
    assert all(any(n.startswith("right_hand/") for n in p) and any(n.startswith("left_hand/") for n in p)
               for p in checker.colliding_pairs(q, "hands"))


def test_pair_ends_are_the_geometry_models_pairs(default_collision):
    """The model's pair index (ends, 'self' before 'env') is read back from pinocchio's own pairs."""
    cm = default_collision
    pairs = [(cp.first, cp.second) for cp in cm.geometry.collisionPairs]
    assert cm.ends.tolist() == [list(p) for p in pairs]
    robot = range(cm.n_robot_geoms)
    assert all(a in robot and b in robot for a, b in cm.ends[cm.subsets["self"]])
    assert all((a in robot) != (b in robot) for a, b in cm.ends[cm.subsets["env"]])


def test_environment_padding(default_scene):
    """A robot link closer to an obstacle than the padding collides; farther away it does not."""
    from planner.collision.checker import build_collision_model
    from planner.model.environment import Obstacle
    from planner.model.geometry import pose

    robot = default_scene.robot
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, robot.q_rest)
    head = robot.frame_placement(robot.q_rest, "Head")[:3, 3] if robot.model.existFrame("Head") else None
    assert head is not None
    results = {}
    for gap in (0.005, 0.03):
        # a thin wall above the head: find its lowest free height by bisection on the unpadded model
        lo, hi = head[2], head[2] + 0.5
        for _ in range(30):
            mid = (lo + hi) / 2
            wall = Obstacle("wall", "box", (1.0, 1.0, 0.01), pose((head[0], head[1], mid)))
            cm0 = build_collision_model(robot, (wall,), CollisionParams(env_padding=0.0))
            lo, hi = (mid, hi) if cm0.checker().in_collision(robot.q_rest) else (lo, mid)
        wall = Obstacle("wall", "box", (1.0, 1.0, 0.01), pose((head[0], head[1], hi + gap)))
        cm = build_collision_model(robot, (wall,), CollisionParams(env_padding=0.01))
        results[gap] = cm.checker().in_collision(robot.q_rest)
    assert results == {0.005: True, 0.03: False}


@pytest.mark.slow
def test_pairs_the_robot_spec_allows_are_never_checked():
    """Baxter's spec allows each upper-arm cover to touch its forearm (the cover's cylinder reaches past the elbow): no
    such pair is a candidate, and the count says how many were left out."""
    from planner.collision.pairs import geometry_link
    from planner.model.robot import load_robot
    from planner.model.robot_spec import load_robot_spec

    robot = load_robot(load_robot_spec("baxter_allegro.toml").source)
    gm = simplified_robot_geometry(robot)
    pairs, _, allowed = _candidate_pairs(robot, gm)
    links = [geometry_link(o.name) for o in gm.geometryObjects]
    allowed_links = {frozenset(p) for p in robot.spec.allowed_collisions}
    assert allowed_links and allowed == 2
    assert not any(frozenset((links[i], links[j])) in allowed_links for i, j in pairs)
    elbow = links.index("left_upper_elbow_visual")
    assert any(elbow in pair for pair in pairs), "the cover is still checked against everything else"


def test_pair_tests_count_the_pairs_that_reach_the_exact_test(default_scene, default_collision):
    """A one-pair subset costs one exact test where its two geometries are in collision and none where they are a metre
    apart (the broad phase drops it); a collision-free check of every pair tests at most every pair, and some."""
    robot, cm = default_scene.robot, default_collision
    checker = cm.checker()
    objs = cm.geometry.geometryObjects
    desk = next(e for e in range(cm.n_robot_geoms, len(objs)) if objs[e].name == "env/desk_top")
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, robot.q_rest)
    pin.updateGeometryPlacements(robot.model, data, cm.geometry, gd := pin.GeometryData(cm.geometry), robot.q_rest)
    desk_z = objs[desk].placement.translation[2]
    pair = next(int(k) for k in cm.subsets["env"] if int(cm.ends[k][1]) == desk and cm.parts[int(cm.ends[k][0])] == "right"
                and gd.oMg[int(cm.ends[k][0])].translation[2] > desk_z + 0.5)
    geom = int(cm.ends[pair][0])
    one = np.array([pair])
    before = checker.pair_tests
    assert not checker.in_collision(robot.q_rest, one)
    assert checker.pair_tests == before, "a pair half a metre apart reached the exact test"
    on_desk = {geom: objs[desk].placement.homogeneous}  # the link moved into the desk for this call
    assert checker.in_collision(robot.q_rest, one, placed=on_desk)
    assert checker.pair_tests == before + 1
    rng = np.random.default_rng(3)
    free = next(q for q in (robot.clip(robot.q_rest + rng.normal(0.0, 0.2, robot.nq)) for _ in range(200))
                if not checker.in_collision(q))
    before = checker.pair_tests
    assert not checker.in_collision(free)
    assert 0 < checker.pair_tests - before <= len(cm.subsets["all"])
