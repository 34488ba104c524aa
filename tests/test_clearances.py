"""Paddings fitted to a transit's ends pair by pair, and the clearance meters that fit them: exactly the pairs nearer
than far, the same distance whatever was measured before, each pair measured once per configuration per situation."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from test_lazy_transit import example_inputs

from planner.motion.result import MotionParams

EXAMPLE = Path(__file__).resolve().parent.parent / "sessions" / "default-example"


@pytest.fixture(scope="module")
def example(tmp_path_factory):
    return example_inputs(tmp_path_factory)


def test_paddings_fitted_pair_by_pair():
    """A transit end near something lowers the padding of the pairs it holds close only: those found are exactly the
    pairs an exhaustive distance query puts near enough, each padded to leave 90 % of its margin over the clearance; a
    pair padded otherwise changes the spacing only of the segments that move it relative to its partner."""

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
