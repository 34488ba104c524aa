"""Each pair checked as densely as its own motion needs (planner/collision/segments.py): the schedule of levels, the
levels a pair gets, what real segments and smoothing ramps test (their pairs' motion between two tests measured by
kinematics alone), the few-pair test without the broad phase, and the bounded cache of level subsets."""
from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin
import pytest

from planner.collision.pair_tables import pair_table
from planner.collision.schedule import level_order
from planner.collision.segments import FEW_PAIRS, LEVEL_SUBSETS, MAX_LEVEL, SegmentChecker, _undominated
from planner.motion.ramps import ramp


@pytest.fixture(scope="module")
def padded(default_collision):
    """The default model padded as the motion's transits are (3 cm from obstacles, 1.2 cm between links)."""
    cm = default_collision
    return dataclasses.replace(cm, params=dataclasses.replace(cm.params, env_padding=0.03, self_padding=0.012))


def test_every_index_is_scheduled_once_the_coarsest_levels_first():
    """Level `top` holds 0, n-1 and the multiples of 2^top; level j < top the odd multiples of 2^j: so a pair of level j,
    tested at levels j..top, is tested at every multiple of 2^j and at both ends."""
    for n in range(2, 300):
        for top in range(0, MAX_LEVEL + 1):
            if top and 2**top > n - 1:
                continue
            levels = level_order(n, top)
            assert [j for j, _ in levels] == sorted({j for j, _ in levels}, reverse=True), "coarsest first"
            seen = np.concatenate([idx for _, idx in levels])
            assert sorted(seen.tolist()) == list(range(n)), f"n={n} top={top}: every index once"
            for j in range(top + 1):
                tested = set(np.concatenate([idx for level, idx in levels if level >= j]).tolist())
                assert set(range(0, n, 2**j)) | {0, n - 1} <= tested, f"n={n} top={top} level {j}"


def test_the_leading_rows_are_those_no_other_row_bounds():
    """A curve's clock reads only the rows no other row bounds in every column (a bounded row never moves farthest): on
    random small-integer rows (many ties, many equal rows), the rows kept are, one each, exactly the distinct rows that
    no other distinct row bounds everywhere (all pairs compared), and every row is bounded by a row kept."""
    rng = np.random.default_rng(3)
    for _ in range(200):
        rows = rng.integers(0, 4, (int(rng.integers(0, 40)), int(rng.integers(1, 5)))).astype(float)
        kept = _undominated(rows)
        assert kept.shape[1:] == rows.shape[1:]
        distinct = {tuple(r) for r in rows}
        oracle = {r for r in distinct if not any(o != r and all(a >= b for a, b in zip(o, r)) for o in distinct)}
        assert sorted(map(tuple, kept)) == sorted(oracle)
        assert all(any(np.all(r <= k) for k in kept) for r in rows)


def test_each_set_of_moving_joints_leads_with_rows_that_bound_all_the_others(padded):
    """A curve's clock reads, for the joints it moves, rows of the subset that bound every row of it there (so the
    largest product with speeds >= 0 is the same as over all rows): for the first set of joints a checker sees (picked
    among all rows) and for the later ones (picked among the rows no other bounds over all joints), in any order."""
    rng = np.random.default_rng(7)
    for _ in range(3):
        seg = SegmentChecker(padded, 0.01, 0.005)
        rows = seg.weights("all")
        for _ in range(4):
            moving = np.sort(rng.choice(rows.shape[1], int(rng.integers(1, rows.shape[1])), replace=False))
            lead = seg._leading("all", moving)
            assert {tuple(r) for r in lead} <= {tuple(r) for r in rows[:, moving]}, "a leading row that is no row of the subset"
            assert all(np.any(np.all(r <= lead, axis=1)) for r in rows[:, moving]), "a row no leading row bounds"


def test_a_pair_gets_the_sparsest_spacing_that_keeps_its_bound(padded):
    """A pair whose displacement spans `need` of the n - 1 intervals at most is checked every 2^j-th configuration with
    2^j need <= n - 1, the largest such power (up to MAX_LEVEL and n - 1): between two of its checks it moves no more
    than the pair that sets the count moves between two checks."""
    seg = SegmentChecker(padded, 0.01, 0.005)
    rows = seg.weights("all")
    rng = np.random.default_rng(3)
    for _ in range(300):
        n = int(rng.integers(3, 200))
        need = rng.uniform(0.0, n - 1, len(rows)) * (rng.random(len(rows)) < 0.9)
        need[int(rng.integers(len(rows)))] = n - 1  # the pair that sets n
        levels = seg.pair_levels("all", need, n)
        per_pair = need[seg._pair_rows["all"]]
        top = min(MAX_LEVEL, int(np.floor(np.log2(n - 1))))
        assert levels is not None and levels.min() == 0 and levels.max() <= top
        assert np.all(2.0**levels * per_pair <= (n - 1) * (1 + 1e-12)), "a pair checked too sparsely"
        sparser = 2.0 ** (levels + 1) * per_pair > (n - 1)
        assert np.all(sparser | (levels == top)), "a pair checked more densely than it needs"


def _recording(seg: SegmentChecker, monkeypatch) -> list[tuple[np.ndarray, np.ndarray]]:
    """Every check the segment checker makes, as (configuration, pair indices tested)."""
    checks: list[tuple[np.ndarray, np.ndarray]] = []
    checker = seg.checker
    full, few = checker.in_collision, checker.few_collide

    def in_collision(q, subset="all", placed=None, margins=None):
        pairs = seg.cm.subsets[subset] if isinstance(subset, str) else subset
        checks.append((np.array(q), np.array(pairs)))
        return full(q, subset, placed, margins)

    def few_collide(q, pairs, margins):
        checks.append((np.array(q), np.array(pairs)))
        return few(q, pairs, margins)

    monkeypatch.setattr(checker, "in_collision", in_collision)
    monkeypatch.setattr(checker, "few_collide", few_collide)
    return checks


def _points(geometry) -> np.ndarray | None:
    """Points whose motion bounds the geometry's: a hull's vertices, a box's corners, a sphere's centre; None for an
    obstacle's other shapes."""
    if hasattr(geometry, "points"):
        return np.asarray(geometry.points())
    if hasattr(geometry, "halfSide"):
        return np.array(np.meshgrid(*[[-h, h] for h in geometry.halfSide])).reshape(3, -1).T
    if hasattr(geometry, "radius") and not hasattr(geometry, "halfLength"):
        return np.zeros((1, 3))
    return None


def _relative_motion(model: pin.Model, gm: pin.GeometryModel, pair: tuple[int, int], qa: np.ndarray, qb: np.ndarray) -> float:
    """How far one geometry's points move in the other's frame between qa and qb, sampled along the straight line:
    pinocchio's kinematics alone (the pair's distance changes by no more than this)."""
    data, gd = model.createData(), pin.GeometryData(gm)
    moved, frame = (int(pair[0]), int(pair[1]))
    pts = _points(gm.geometryObjects[moved].geometry)
    if pts is None:
        moved, frame = frame, moved
        pts = _points(gm.geometryObjects[moved].geometry)

    def placed(q):
        pin.updateGeometryPlacements(model, data, gm, gd, q)
        rel = gd.oMg[frame].inverse() * gd.oMg[moved]
        return pts @ rel.rotation.T + rel.translation

    start = placed(qa)
    return max(float(np.linalg.norm(placed(qa + s * (qb - qa)) - start, axis=1).max()) for s in np.linspace(0, 1, 9)[1:])


@pytest.mark.slow
def test_a_real_segment_tests_each_pair_at_its_own_spacing_and_no_sparser(default_scene, padded, monkeypatch):
    """Along free segments of the default robot, the pairs past the coarsest level are tested at every multiple of
    their spacing; between two of a pair's tests its geometries move (measured by kinematics alone) no more than twice
    the pair's margin over its clearance; and a pair is tested at far fewer configurations than the segment has."""
    cm = padded
    env_c, self_c = 0.01, 0.004
    seg = SegmentChecker(cm, env_c, self_c)
    checks = _recording(seg, monkeypatch)
    robot = default_scene.robot
    rng = np.random.default_rng(0)
    allow = cm.paddings() - np.where(np.isin(np.arange(len(cm.ends)), cm.subsets["env"]), env_c, self_c)
    arms = np.concatenate([robot.arm_idx[a] for a in robot.spec.arm_names])
    tested_sparsely = segments = 0
    for _ in range(60):
        qa, qb = robot.q_rest.copy(), robot.q_rest.copy()
        qb[arms] = np.clip(qb[arms] + rng.normal(0.0, 0.3, len(arms)), robot.lower[arms], robot.upper[arms])
        if segments == 5 or not seg.free(qb, "env"):
            continue
        checks.clear()
        if not seg.segment_free(qa, qb, "env"):
            continue
        segments += 1
        n = int(seg.steps(qa, qb, "env")[0])
        s = np.array([float(np.dot(q - qa, qb - qa) / np.dot(qb - qa, qb - qa)) for q, _ in checks])
        assert len(s) == n, "every configuration of the segment is checked"
        pairs = cm.subsets["env"]
        counts = np.zeros(len(cm.ends), int)
        for _, tested in checks:
            counts[tested] += 1
        sparse = [int(k) for k in pairs if counts[k] < n]
        tested_sparsely += len(sparse)
        for k in rng.choice(sparse, min(25, len(sparse)), replace=False):
            at = np.sort(np.round(s[[k in set(t.tolist()) for _, t in checks]] * (n - 1)).astype(int))
            assert at[0] == 0 and at[-1] == n - 1, "both ends"
            gaps = np.diff(at)
            spacing = int(gaps.max())
            assert spacing & (spacing - 1) == 0 and np.all(at[:-1] % spacing == 0), "at every multiple of its spacing"
            for a, b in zip(at[:-1], at[1:]):
                moved = _relative_motion(robot.model, cm.geometry, tuple(cm.ends[k]), qa + a / (n - 1) * (qb - qa),
                                         qa + b / (n - 1) * (qb - qa))
                assert moved <= 2 * allow[k] + 1e-9, f"pair {k} moved {moved:.4f} m between two of its tests"
    assert segments == 5 and tested_sparsely, "no segment had a pair tested less densely than the one that sets its count"


def test_few_pairs_answer_as_the_broad_phase_does(default_scene, default_collision):
    """A check of a few pairs tested one by one answers as the broad-phase check of the same pairs, near and far from
    collisions, with the paddings as given."""
    cm = default_collision
    checker = cm.checker()
    robot = default_scene.robot
    rng = np.random.default_rng(1)
    margins = pair_table(cm, cm.paddings() + 0.02)
    hits = 0
    for _ in range(300):
        q = np.clip(robot.q_rest + rng.normal(0.0, 0.6, robot.nq), robot.lower, robot.upper)
        pairs = np.sort(rng.choice(len(cm.ends), int(rng.integers(1, FEW_PAIRS + 1)), replace=False))
        if rng.random() < 0.5:
            colliding = checker.colliding(q, "all", margins)
            if colliding:
                pairs = np.unique(np.concatenate([pairs[:-1], [rng.choice(colliding)]]))
        answer = checker.in_collision(q, pairs, margins=margins)
        assert checker.few_collide(q, pairs, margins) == answer
        checker.forget(pairs)
        hits += answer
    assert 30 < hits < 270, hits


@pytest.mark.slow
def test_few_pairs_with_the_object_answer_as_its_screened_check_does(default_scene, default_collision):
    """With the object beside the right hand (its hull screening its mesh), a few pairs tested one by one, the hull
    first, answer as the model's own check of those pairs, which tries the hull first too."""
    from planner.collision.shapes import coal_convex, coal_mesh
    from planner.collision.situation import Situation, situation_model

    robot = default_scene.robot
    pose = robot.frame_placement(robot.q_rest, robot.palm_frame("right"))
    pose[:3, 3] += pose[:3, 2] * 0.06
    moving = np.concatenate([robot.torso_idx] + [robot.arm_idx[a] for a in robot.spec.arm_names])
    mesh = default_scene.object_mesh
    cm = situation_model(default_collision, coal_mesh(mesh), Situation(None, pose), (), moving, coal_convex(mesh.convex_hull))
    assert cm.twins is not None
    checker = cm.checker()
    margins = pair_table(cm, cm.paddings())
    objects = cm.subsets["object"]
    rng = np.random.default_rng(5)
    answers = []
    for _ in range(200):
        q = robot.q_rest.copy()
        q[moving] += rng.normal(0.0, 0.08, len(moving))
        pairs = np.sort(rng.choice(objects, min(FEW_PAIRS, len(objects)), replace=False))
        answer = checker.in_collision(q, pairs, margins=margins)
        assert checker.few_collide(q, pairs, margins) == answer
        checker.forget(pairs)
        answers.append(answer)
    assert 10 < sum(answers) < 190, sum(answers)


def test_level_subsets_are_kept_only_while_recent(default_scene, padded):
    """Many segments of different directions leave the checker at most LEVEL_SUBSETS subsets of levels (with their
    collision tables) besides the named ones."""
    seg = SegmentChecker(padded, 0.01, 0.004)
    robot = default_scene.robot
    rng = np.random.default_rng(2)
    for _ in range(120):
        qb = np.clip(robot.q_rest + rng.normal(0.0, 0.3, robot.nq), robot.lower, robot.upper)
        seg.segment_free(robot.q_rest, qb, "env", ends=False)
    assert 0 < len(seg._levels) <= LEVEL_SUBSETS
    assert len(seg.checker._tables) <= LEVEL_SUBSETS + len(padded.subsets)


def random_ramp(robot, rng: np.random.Generator, spread: float):
    """A parabolic ramp from the rest pose to the arms moved by about `spread` rad each, leaving at a random arm
    velocity (as the smoothing's curves do), at 1 rad/s and 2 rad/s^2; None when no ramp joins them."""
    arms = np.concatenate([robot.arm_idx[a] for a in robot.spec.arm_names])
    qa, qb, va = robot.q_rest.copy(), robot.q_rest.copy(), np.zeros(robot.nq)
    qb[arms] = np.clip(qb[arms] + rng.normal(0.0, spread, len(arms)), robot.lower[arms], robot.upper[arms])
    va[arms] = rng.uniform(-0.3, 0.3, len(arms))
    return ramp(qa, va, qb, np.zeros(robot.nq), np.ones(robot.nq), np.full(robot.nq, 2.0))


class PairMotion:
    """How each pair's geometries move relative to each other along a curve: pinocchio's kinematics alone on `samples`
    evenly spaced times, and, for a pair, its moving geometry's points in the other's frame (see `_points`)."""

    def __init__(self, cm, curve, samples: int):
        model, gm = cm.robot.model, cm.geometry
        data, gd = model.createData(), pin.GeometryData(gm)
        self.cm, self.times = cm, np.linspace(0.0, curve.duration, samples)
        self.dense = curve.positions(self.times)
        poses = []
        for q in self.dense:
            pin.updateGeometryPlacements(model, data, gm, gd, q)
            poses.append([gd.oMg[g].homogeneous for g in range(len(gm.geometryObjects))])
        self.poses = np.array(poses)

    def sample_of(self, q: np.ndarray) -> int:
        """The sample nearest a configuration of the curve."""
        return int(np.argmin(np.linalg.norm(self.dense - q, axis=1)))

    def points(self, pair: int) -> np.ndarray:
        """(samples, points, 3) one geometry's points of the pair in the other's frame, at every sample."""
        objects = self.cm.geometry.geometryObjects
        moved, frame = (int(g) for g in self.cm.ends[pair])
        pts = _points(objects[moved].geometry)
        if pts is None:
            moved, frame = frame, moved
            pts = _points(objects[moved].geometry)
        rel = np.linalg.inv(self.poses[:, frame]) @ self.poses[:, moved]
        return np.einsum("mij,pj->mpi", rel[:, :3, :3], pts) + rel[:, None, :3, 3]


@pytest.mark.slow
def test_a_curve_tests_each_pair_often_enough_for_its_own_motion(default_scene, padded, monkeypatch):
    """Along random parabolic ramps from the rest pose (the smoothing's curves), a pair tested at fewer configurations
    than the curve's checks moves, between two of its tests (measured by kinematics on 1,000 samples of the curve), no
    more than twice its margin over its clearance."""
    cm = padded
    env_c, self_c = 0.01, 0.004
    seg = SegmentChecker(cm, env_c, self_c)
    checks = _recording(seg, monkeypatch)
    robot = default_scene.robot
    allow = cm.paddings() - np.where(np.isin(np.arange(len(cm.ends)), cm.subsets["env"]), env_c, self_c)
    rng = np.random.default_rng(4)
    curves = tested_sparsely = 0
    while curves < 2:
        curve = random_ramp(robot, rng, 0.3)
        checks.clear()
        qb = None if curve is None else curve.end
        if curve is None or not seg.free(qb, "env") or seg.curve_first_hit(curve, "env") is not None:
            continue
        curves += 1
        motion = PairMotion(cm, curve, 1000)
        at = np.array([motion.sample_of(q) for q, _ in checks])
        counts = np.zeros(len(cm.ends), int)
        for _, tested in checks:
            counts[tested] += 1
        sparse = [int(k) for k in cm.subsets["env"] if counts[k] < len(checks)]
        tested_sparsely += len(sparse)
        for k in rng.choice(sparse, min(25, len(sparse)), replace=False):
            world = motion.points(k)
            tested = np.unique(at[[k in set(t.tolist()) for _, t in checks]])
            assert tested[0] == 0 and tested[-1] == len(motion.dense) - 1, "both ends"
            for a, b in zip(tested[:-1], tested[1:]):
                moved_by = float(np.linalg.norm(world[a:b + 1] - world[a], axis=2).max())
                assert moved_by <= 2 * allow[k] + 2e-4, f"pair {k} moved {moved_by:.4f} m between two of its tests"
    assert tested_sparsely, "no curve had a pair tested less densely than the one that sets its count"


@pytest.mark.slow
def test_a_shoulder_swing_is_checked_neither_too_sparsely_nor_twice_too_densely(default_scene, padded, monkeypatch):
    """The displacement bound is nearly tight for a shoulder swinging the whole arm: along a rest-to-rest swing of each
    arm's first two joints (a curve, timed as the smoothing's are), every pair tested at every check moves between two
    consecutive checks (measured by kinematics on the hull vertices) at most twice its margin over its clearance, and
    some pair more than half of that. So a schedule twice as sparse as the bound asks would break the first assertion:
    the oracle of the tests above, which often finds displacements far below the bound, is not blind to one."""
    from planner.motion.trajectory import rest_to_rest

    cm = padded
    seg = SegmentChecker(cm, 0.01, 0.004)
    checks = _recording(seg, monkeypatch)
    robot = default_scene.robot
    model, gm = robot.model, cm.geometry
    data, gd = model.createData(), pin.GeometryData(gm)
    allow = cm.paddings() - np.where(np.isin(np.arange(len(cm.ends)), cm.subsets["env"]), 0.01, 0.004)
    efficiency = []
    for j in [robot.arm_idx[a][i] for a in robot.spec.arm_names for i in (0, 1)]:
        qa = robot.q_rest.copy()
        qb = qa.copy()
        qb[j] = qa[j] + 1.0 if qa[j] + 1.0 <= robot.upper[j] else qa[j] - 1.0
        curve = rest_to_rest(np.stack([qa, qb]), np.ones(robot.nq), np.full(robot.nq, 2.0))
        checks.clear()
        assert seg.curve_first_hit(curve, "env") is None, "the swing must be free for every check to be made"
        angles = np.sort([q[j] for q, _ in checks])
        every = set.intersection(*[set(t.tolist()) for _, t in checks])
        placed = []  # per interval between two checks, every geometry's world pose at 6 configurations along it
        for a, b in zip(angles[:-1], angles[1:]):
            along = []
            for x in np.linspace(a, b, 6):
                q = qa.copy()
                q[j] = x
                pin.updateGeometryPlacements(model, data, gm, gd, q)
                along.append(np.array([g.homogeneous for g in gd.oMg]))
            placed.append(along)
        for k in every:
            moved, frame = (int(g) for g in cm.ends[k])
            if _points(gm.geometryObjects[moved].geometry) is None:
                moved, frame = frame, moved
            pts = _points(gm.geometryObjects[moved].geometry)
            worst = 0.0
            for along in placed:
                seen = []
                for poses in along:
                    rel = np.linalg.inv(poses[frame]) @ poses[moved]
                    seen.append(pts @ rel[:3, :3].T + rel[:3, 3])
                worst = max(worst, max(float(np.linalg.norm(p - seen[0], axis=1).max()) for p in seen))
            efficiency.append(worst / (2 * allow[k]))
    assert max(efficiency) <= 1.0 + 1e-6, f"a pair moved {max(efficiency):.2f} of its allowed displacement between two checks"
    assert max(efficiency) > 0.55, f"the bound is looser than a 2x-sparser schedule could hide ({max(efficiency):.2f})"
