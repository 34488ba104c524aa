"""What a transit checks and counts: every check and pair test of a transit counted, the arm moved alone on its own
budget, the Carry using the roadmap's nodes, dense checks only beside a tight end, the hull screen changing no answer,
situations made alike sharing one collision model."""
from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from oracle import Oracle
from test_grasp_list import _crossings
from test_lazy_transit import example_inputs, phase_planner

from planner.motion.space import JointSpace

EXAMPLE = Path(__file__).resolve().parent.parent / "sessions" / "default-example"


@pytest.fixture(scope="module")
def example(tmp_path_factory):
    return example_inputs(tmp_path_factory)


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
    planner = phase_planner(scene, roadmap, baseline)
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
        planner = phase_planner(scene, roadmap, baseline)
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

    scene, roadmap, _ = example
    robot = scene.robot
    motion = Session.open(EXAMPLE).result("motion")
    carry = np.flatnonzero((motion.phase == PHASES.index("Carry")) & (motion.active == -1) & (motion.holder >= 0))
    run = np.split(carry, np.flatnonzero(np.diff(carry) > 1) + 1)[0]  # the first stretch: the transit
    q_start, q_goal = motion.q[run[0]], motion.q[run[-1]]
    arm = motion.arms[int(motion.holder[run[0]])]
    planner = phase_planner(scene, roadmap)
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
    planner = phase_planner(scene, roadmap)
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
    planner = phase_planner(scene, roadmap)
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
    validities = phase_planner(scene, roadmap).validities
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
