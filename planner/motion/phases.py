"""The four phases of the task (paper V-B) as pieces: transit motions on the Super Graph and contact motions.

Grasp: transit to the pre-grasp (the picking hand backed off along its approach direction and raised,
fingers open), the fingers to their pre-shape, a straight approach, the fingers closing. Carry: the
object lifted off its support, transit to the exchange with the placing hand at its pre-grasp, its
approach and closing, then the picking hand letting go (its touching fingers open part way) and
retreating. Place: the picking arm alone away from the object (to where it is at the placement or at
the end), transit with the placing hand to near the placement, set down, let go, retreat. Rest:
transit to the final configuration, where both hands open fully (opened near the object, fingers
that wrapped around it would hit it).
The object is lifted off and set down along the freest of several directions (vertical first when
it is free: a lamp may hang over a placement), so that transits start and end where they can leave.
Every contact motion is made, and every transit end checked, before any transit is searched: a
double grasp that cannot work is given up in a fraction of a second. Where a transit fails, the next
candidate end of that hand (pre-grasp, set-down) is tried. A hand backs off from a grasp along its
approach direction first, then along directions tilted from it (where fingers coming straight in
would sweep the object or its support).
Straight hand motions are IK waypoints of the arm and the torso; while the other hand holds the
object, its palm is held still by the same IK, so the object does not move. Every piece is checked
with the validity of its situation; a piece that fails raises `PieceFailed` naming the phase and the
part.
"""
from __future__ import annotations

import dataclasses
import itertools
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin

from planner.collision.checker import CollisionChecker, CollisionModel
from planner.collision.hand_placement import world_aabb
from planner.collision.segments import geometry_radii
from planner.collision.situation import Situation, finger_geometries, fingertip_geometries, for_motion, situation_base
from planner.collision.validity import Clearances, Graded, Profile, Validity, far, fits, make_validity
from planner.core.forked import forked_map
from planner.handover.arm_ik import ArmIK
from planner.handover.reach import approach_direction
from planner.model.geometry import coal_convex, coal_mesh, transform3s
from planner.model.task import Scene
from planner.motion.graph import MotionGraph
from planner.motion.result import PHASES
from planner.motion.space import JointSpace
from planner.motion.transit import LazyTransit, TransitFailed, TransitParams, TransitStats, rrt_transit, shortcut, shortcut_vertices


@dataclass(frozen=True)
class Piece:
    """A checked polyline of one phase, with the object's situation along it."""

    phase: int
    part: str
    path: np.ndarray  # (k, nq), k >= 2
    situation: Situation
    hand: str | None = None  # the arm whose hand works near the object in a contact motion (None: transit)


class PieceFailed(Exception):
    """A piece that cannot be made; `why` may be a function, called only when the message is read (naming the
    colliding pairs takes a full check, and most failures are of candidates that are never reported)."""

    def __init__(self, phase: int, part: str, why: str | Callable[[], str]):
        super().__init__(phase, part)
        self.phase, self.part, self._why = phase, part, why

    @property
    def why(self) -> str:
        if callable(self._why):
            self._why = self._why()
        return self._why

    def __str__(self) -> str:
        return f"{PHASES[self.phase]} phase, {self.part}: {self.why}"


@dataclass(frozen=True)
class HandGrasp:
    """One hand's grasp: its arm, the palm pose in the object frame, the finger values and the touching fingers."""

    arm: str
    palm_in_object: np.ndarray
    fingers: np.ndarray
    touching: list


class PhasePlanner:
    """Builds the pieces of one double grasp; keeps per-phase Table I figures in `stats`."""

    def __init__(self, scene: Scene, cm: CollisionModel, graph: MotionGraph, transit: Profile, contact: Profile,
                 params, rng: np.random.Generator, baseline: bool):
        self.scene, self.robot, self.cm, self.graph = scene, scene.robot, cm, graph
        self.transit_profile, self.contact_profile, self.p, self.rng, self.baseline = transit, contact, params, rng, baseline
        self.shape = coal_mesh(scene.object_mesh)
        self.hull = coal_convex(scene.object_mesh.convex_hull)  # screens the mesh: see situation_model
        self.data = self.robot.model.createData()
        self.iks: dict[tuple[str, ...], ArmIK] = {}  # one solver (and its scratch data) per set of arms
        self.stats = [TransitStats() for _ in PHASES]
        self.transit_params = TransitParams.of(params)
        robot = self.robot
        self.transit_idx = np.concatenate([robot.torso_idx] + [robot.arm_idx[a] for a in robot.spec.arm_names])
        self.open = robot.q_rest
        self.radii = geometry_radii(cm)
        self.situation_radii: dict[tuple[int, bytes], np.ndarray] = {}  # see validity
        self.bases: dict[Situation, CollisionModel] = {}  # one model (and collision data) per situation ...
        self.models: dict[tuple, CollisionModel] = {}  # ... and its subsets for each kind of motion
        self.validities: dict[tuple, Validity] = {}
        self.distances: dict[int, Clearances] = {}
        self.checkers: dict[int, CollisionChecker] = {}  # per situation (its geometry): one scratch data for all checks
        # (their kinematics in self.data, which every check recomputes)
        self.checked: dict[tuple[int, bytes], np.ndarray | None] = {}  # see valid
        self.measured: dict[tuple[int, bytes], dict[int, float]] = {}  # see clearances
        self.finger_names = {arm: self.finger_of_geometry(arm) for arm in robot.spec.arm_names}

    # ----- kinematics
    def palm(self, q: np.ndarray, arm: str) -> np.ndarray:
        pin.framesForwardKinematics(self.robot.model, self.data, q)
        return self.data.oMf[self.robot.frame_id(self.robot.palm_frame(arm))].homogeneous.copy()

    def _ik(self, q: np.ndarray, arm: str, target: np.ndarray, keep: str | None, tol: float = 1e-3,
            damping: float = 1e-4) -> np.ndarray | None:
        """q with the torso and the arm moved so its palm is at target; the palm of `keep` (a hand holding the object)
        stays where it is. None when IK misses."""
        arms, targets = (arm,), [target]
        if keep is not None:
            arms, targets = (arm, keep), [target, self.palm(q, keep)]
        if arms not in self.iks:
            self.iks[arms] = ArmIK(self.robot, arms)
        result = self.iks[arms].solve(np.array(targets), q, 60, tol, 10 * tol, damping=damping, stall=20)
        return result.q if result.within(tol, 10 * tol) else None

    def refine(self, q: np.ndarray, arm: str, target: np.ndarray, keep: str | None, phase: int, part: str) -> np.ndarray:
        """q with the palm of `arm` at target to 0.1 mm / 1 mrad (the double grasps hold 2 mm), `keep`'s palm still."""
        found = self._ik(q, arm, target, keep, 1e-4, damping=1e-9)
        if found is None:
            raise PieceFailed(phase, part, "the arm cannot put its palm exactly at the grasp")
        return found

    def straight(self, q: np.ndarray, arm: str, offset: np.ndarray, keep: str | None, phase: int, part: str) -> np.ndarray:
        """IK waypoints moving the arm's palm by a world offset in a straight line, `keep`'s palm still: (steps+1, nq)."""
        t = time.perf_counter()
        start = self.palm(q, arm)
        out = [q]
        for s in np.linspace(0.0, 1.0, self.p.straight_steps + 1)[1:]:
            target = start.copy()
            target[:3, 3] += s * offset
            nxt = self._ik(out[-1], arm, target, keep)
            if nxt is None:
                raise PieceFailed(phase, part, f"the arm cannot move its palm {np.linalg.norm(offset):.3f} m in a straight line")
            out.append(nxt)
        self.stats[phase].seconds_contact += time.perf_counter() - t
        return np.array(out)

    def retreats(self, q: np.ndarray, arm: str, keep: str | None, hover: bool, phase: int, part: str,
                 leaving: bool = False) -> list[Iterator[np.ndarray]]:
        """Two groups of candidate IK polylines from q (the palm at a grasp) backing off by the pre-grasp distance: along
        the approach direction (that distance, farther, nearer), then rising by the lift height when `hover` (the object
        rests on a support there; elsewhere rising is the last resort); then tilted 30° and 55° from the approach
        direction in six directions each (where fingers moving along it would sweep the object or a support), rising
        likewise. Each group is computed only when it is reached; candidates the arm cannot follow are skipped.
        `leaving` (a hand letting go in the air): farther first. Its fingers, opened part way, can still be a millimetre
        from the object after the pre-grasp distance, and the transit that follows checks as densely as its ends need."""
        back = self.backoff(q, arm)
        rises = (1.0, 1.0, 2.0, 1.0) if hover else (0.0, 0.0, 0.0, 1.0)
        scales = (1.0, 1.7, 1.0, 0.5) if hover else (1.7, 1.0, 0.5, 1.0) if leaving else (1.0, 1.7, 0.5, 1.0)
        along = [(scale * back, rise) for scale, rise in zip(scales, rises)]
        axis = back / np.linalg.norm(back)
        u = np.cross(axis, [0.0, 0.0, 1.0] if abs(axis[2]) < 0.9 else [1.0, 0.0, 0.0])
        u /= np.linalg.norm(u)
        v = np.cross(axis, u)
        tilted = [(np.linalg.norm(back) * (np.cos(t) * axis + np.sin(t) * (np.cos(az) * u + np.sin(az) * v)), rises[0])
                  for t in np.radians([30.0, 55.0]) for az in np.radians(np.arange(0.0, 360.0, 60.0))]
        return [self._backing(q, arm, keep, offsets, phase, part) for offsets in (along, tilted)]

    def _backing(self, q: np.ndarray, arm: str, keep: str | None, offsets: list[tuple[np.ndarray, float]], phase: int,
                 part: str) -> Iterator[np.ndarray]:
        """The IK polylines moving the palm from q by each world offset, then up by `rise` lift heights (see retreats)."""
        up = np.array([0.0, 0.0, self.p.lift])
        for offset, rise in offsets:
            try:
                path = self.straight(q, arm, offset, keep, phase, part)
                if rise:
                    path = np.concatenate([path, self.straight(path[-1], arm, rise * up, keep, phase, part)[1:]])
            except PieceFailed:
                continue
            yield path

    def shaped(self, grasp: HandGrasp, groups: list[Iterator[np.ndarray]], situation: Situation,
               closing: Situation) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """(pre-shape, approach path reversed with the fingers in it) candidates, group by group (see retreats): each
        retreat with the fingers shaped for it (see preshape)."""
        for group in groups:
            for path in group:
                pre = self.preshape(grasp, path, situation, closing)
                yield pre, np.array([self.with_fingers(q, grasp.arm, pre) for q in path])

    def preshape(self, grasp: HandGrasp, path: np.ndarray, situation: Situation, closing: Situation) -> np.ndarray:
        """Finger values for shaping the open hand at the pre-grasp, approaching along a retreat path (reversed) and
        closing from there (in the `closing` situation, the touching fingertips allowed): open by the pre-shape fraction;
        a finger the shaping, the approach or the closing makes collide is tried wide open (its spreading joint too: an
        opposed thumb, opened only at its flexing joints, can reach across the object), then open by half, a fifth, not
        at all (see per_finger)."""
        open_hand = self.open[self.robot.hand_idx[grasp.arm]]
        levels = [self.opened(grasp, self.p.preshape), open_hand] + [
            self.opened(grasp, f) for f in (0.5 * self.p.preshape, 0.2 * self.p.preshape)] + [grasp.fingers]

        def collisions(pre: np.ndarray) -> list[tuple[str, str]]:
            approach = np.array([self.with_fingers(q, grasp.arm, pre) for q in path])[::-1]
            validity = self.validity(self.model(situation, approach[0], np.flatnonzero(np.ptp(approach, axis=0) > 0)),
                                     self.contact_profile)
            if not self.valid(validity, approach):
                return self.collisions(validity, approach)
            shaping = self.finger_collisions(self.with_fingers(approach[0], grasp.arm, open_hand), grasp.arm, pre, situation)
            return shaping or self.finger_collisions(approach[-1], grasp.arm, grasp.fingers, closing)

        return self.per_finger(grasp, levels, collisions)

    def letting_go(self, grasp: HandGrasp, q: np.ndarray, situation: Situation) -> np.ndarray:
        """Finger values letting go of the object held at q: the touching fingers open by the release fraction; one the
        opening makes collide (a thumb extending into the support) opens by half, a fifth, or stays (see per_finger)."""
        levels = [self.opened(grasp, f * self.p.release, True) for f in (1.0, 0.5, 0.2)] + [grasp.fingers]
        return self.per_finger(grasp, levels, lambda values: self.finger_collisions(q, grasp.arm, values, situation))

    def per_finger(self, grasp: HandGrasp, levels: list[np.ndarray], collisions: Callable[[np.ndarray], list]) -> np.ndarray:
        """Finger values with each finger at one of `levels` (hand values, in order of preference): all start at the
        first; while `collisions` of the values names pairs, every finger in them moves to its next level (opening a
        finger swings it out, into the support or the other hand as often as away from the object). Stops when nothing
        collides, or when a colliding pair has no finger of this hand or a finger is at its last level (the last values
        are returned: the piece built from them fails with its message)."""
        arm = grasp.arm
        hand, fingers, of_geometry = self.robot.hand_idx[arm], self.robot.finger_idx[arm], self.finger_names[arm]
        level = dict.fromkeys(fingers, 0)
        while True:
            values = grasp.fingers.copy()
            for f, idx in fingers.items():
                at = np.isin(hand, idx)
                values[at] = levels[level[f]][at]
            per_pair = [{of_geometry[n] for n in pair if n in of_geometry} for pair in collisions(values)]
            hit = set().union(*per_pair)
            if not per_pair or not all(per_pair) or any(level[f] == len(levels) - 1 for f in hit):
                return values
            for f in hit:
                level[f] += 1

    def finger_of_geometry(self, arm: str) -> dict[str, str]:
        """Geometry name -> finger name, for the geometries an arm's finger joints move."""
        model, objects = self.robot.model, self.cm.geometry.geometryObjects
        joint_finger = {int(j): f for f, idx in self.robot.finger_idx[arm].items() for j in idx}
        return {objects[g].name: joint_finger[model.joints[objects[g].parentJoint].idx_q]
                for g in finger_geometries(self.cm, arm).tolist()}

    def ready(self, q: np.ndarray, situation: Situation, phase: int, part: str) -> float:
        """PieceFailed unless a transit can start or end at q in the situation: q is valid with the transit paddings
        fitted to its clearances, as a transit checks its ends (see validity.fits). Returns how free q is: the
        smallest share of a transit padding it keeps beyond the clearance guaranteed (1: as free as a roadmap node, so
        the transit's checks are as sparse as the roadmap's)."""
        t0 = time.perf_counter()
        model = self.model(situation, q, self.transit_idx)
        near, meter = self.clearances(model, q), self.meter(model)
        have = meter.by_kind(near)
        self.stats[phase].seconds_contact += time.perf_counter() - t0
        if not fits(self.transit_profile, have):
            end = lambda: self.validity(model, self.transit_profile, meter.fitted_pairs(self.transit_profile, near))  # noqa: E731
            raise PieceFailed(phase, part, lambda: f"ends too near something to start a transit ({_pairs(end().first_collision(q[None]))})")
        t = self.transit_profile
        return min(1.0, *((have[k] - keep) / (pad - keep) for k, pad, keep in (
            ("env", t.env_padding, t.env_clearance), ("self", t.self_padding, t.self_clearance),
            ("object", t.object_padding, t.object_clearance))))

    def meter(self, model: CollisionModel) -> Clearances:
        """The clearance measure of a situation's model over its moving pairs (scratch data built once per model)."""
        if id(model) not in self.distances:
            self.distances[id(model)] = Clearances(model, "moving", far(self.transit_profile), self.checker(model))
        return self.distances[id(model)]

    def checker(self, model: CollisionModel) -> CollisionChecker:
        """The collision scratch data of a situation, shared by the validities and clearance meters of all its motions
        (each pads and picks the pairs its own way): pinocchio's is costly to make, and a forked worker
        must copy it."""
        if id(model.geometry) not in self.checkers:
            self.checkers[id(model.geometry)] = CollisionChecker(model, self.data)
        return self.checkers[id(model.geometry)]

    def clearances(self, model: CollisionModel, q: np.ndarray) -> dict[int, float]:
        """A situation's near pairs at q and their distances (see validity.Clearances), measured once per configuration
        (a transit's ends were measured when they were found ready)."""
        key = (id(model), q.tobytes())
        if key not in self.measured:
            self.measured[key] = self.meter(model)(q)
        return self.measured[key]

    def validity(self, model: CollisionModel, profile: Profile, pair_padding: tuple[tuple[int, float], ...] = ()) -> Validity:
        """The validity of a situation's model over its moving pairs, some pairs padded otherwise (see
        Clearances.fitted_pairs); one validity per model and paddings. The displacement radii are the robot's, computed
        once, and the object's, once for each place it hangs from (its parent joint and placement)."""
        key = (id(model), profile, pair_padding)
        if key not in self.validities:
            held = model.geometry.geometryObjects[-1]  # the object or its hull, added last: both hang where it does
            where = (held.parentJoint, held.placement.homogeneous.tobytes())
            if where not in self.situation_radii:
                self.situation_radii[where] = geometry_radii(model, self.radii)
            self.validities[key] = make_validity(model, profile, "moving", self.situation_radii[where], pair_padding,
                                                 self.checker(model))
        return self.validities[key]

    def backoff(self, q: np.ndarray, arm: str) -> np.ndarray:
        """World offset that backs the arm's palm off along its approach direction by the pre-grasp distance."""
        palm = self.palm(q, arm)
        return -self.p.pregrasp_distance * (palm[:3, :3] @ approach_direction(self.robot, arm))

    def with_fingers(self, q: np.ndarray, arm: str, values: np.ndarray) -> np.ndarray:
        q = q.copy()
        q[self.robot.hand_idx[arm]] = values
        return q

    def opened(self, grasp: HandGrasp, fraction: float, touching_only: bool = False) -> np.ndarray:
        """Finger values with the flexing joints `fraction` of the way from the grasp to the open hand (each finger's first
        joint, which spreads it sideways, stays: opening it swings the finger across the object); only the touching
        fingers' when `touching_only` (letting go: the others stay clear of the object where they are)."""
        hand = self.robot.hand_idx[grasp.arm]
        fingers = self.robot.finger_idx[grasp.arm]
        names = grasp.touching if touching_only else list(fingers)
        flexing = np.concatenate([fingers[f][1:] for f in names])  # a finger's first joint spreads it: it stays
        step = np.where(np.isin(hand, flexing), fraction * (self.open[hand] - grasp.fingers), 0.0)
        return grasp.fingers + step

    # ----- validity
    def model(self, situation: Situation, q: np.ndarray, moving: np.ndarray) -> CollisionModel:
        """The situation's collision model; the hands not at the roadmap's open values at q are those whose pairs
        'changed', and 'moving' has the pairs the coordinates `moving` change (built once per plan for each)."""
        moved = tuple(a for a in self.robot.spec.arm_names
                      if not np.allclose(q[self.robot.hand_idx[a]], self.open[self.robot.hand_idx[a]]))
        key = (situation, moved, np.asarray(moving).tobytes())
        if key not in self.models:
            if situation not in self.bases:
                self.bases[situation] = situation_base(self.cm, self.shape, situation, self.hull)
            self.models[key] = for_motion(self.bases[situation], moved, moving)
        return self.models[key]

    def contact(self, phase: int, part: str, path: np.ndarray, situation: Situation, hand: str | None) -> Piece:
        """A short motion near the object, checked with the contact profile."""
        t = time.perf_counter()
        moving = np.flatnonzero(np.ptp(path, axis=0) > 0)
        validity = self.validity(self.model(situation, path[0], moving), self.contact_profile)
        ok = self.valid(validity, path)
        self.stats[phase].seconds_contact += time.perf_counter() - t
        if not ok:
            raise PieceFailed(phase, part, lambda: f"collides ({_pairs(self.collisions(validity, path))})")
        return Piece(phase, part, np.asarray(path), situation, hand)

    def finger_orders(self, fingers: list[np.ndarray]) -> list[list[np.ndarray]]:
        """Ways for fingers (their joint indices) to move, as stages of joints moving together: all at once, else each
        finger's last joint first, else last, else one joint depth after the other from the tip to the base, else from
        the base to the tip (a finger curling onto a rounded surface sweeps its middle link through it when its joints
        move together; hooking its tip first keeps it outside)."""
        every = np.concatenate(fingers)
        last = np.array([idx[-1] for idx in fingers])
        rest = np.setdiff1d(every, last)
        by_depth = [np.array([idx[-1 - k] for idx in fingers if k < len(idx)]) for k in range(max(map(len, fingers)))]
        return [[every], [last, rest], [rest, last], by_depth, by_depth[::-1]]

    @staticmethod
    def staged(q: np.ndarray, target: np.ndarray, order: list[np.ndarray]) -> np.ndarray:
        """The polyline from q moving each stage's joints to their values in target, stage after stage (stages that move
        nothing dropped; joints in no stage stay as at q)."""
        path = [q]
        for joints in order:
            step = path[-1].copy()
            step[joints] = target[joints]
            if not np.allclose(step, path[-1]):
                path.append(step)
        return np.array(path)

    def finger_motions(self, q: np.ndarray, arm: str, values: np.ndarray) -> list[np.ndarray]:
        """The distinct polylines of the whole hand's fingers from q to `values` by finger_orders; nothing when they are
        there."""
        target = self.with_fingers(q, arm, values)
        paths: list[np.ndarray] = []
        for order in self.finger_orders(list(self.robot.finger_idx[arm].values())):
            path = self.staged(q, target, order)
            if len(path) > 1 and not any(path.shape == p.shape and np.allclose(path, p) for p in paths):
                paths.append(path)
        return paths

    def finger_path(self, q: np.ndarray, arm: str, values: np.ndarray, validity: Validity) -> np.ndarray | None:
        """A valid motion of the fingers from q to `values`: the first valid of finger_motions, else the fingers one
        after the other, each the first valid of its own ways (the others where they are: a thumb closing all at once
        beside a ring finger hooking its tip first); None when a finger has no valid way."""
        for path in self.finger_motions(q, arm, values):
            if self.valid(validity, path):
                return path
        target = self.with_fingers(q, arm, values)
        path = q[None]
        for idx in self.robot.finger_idx[arm].values():
            ways = [self.staged(path[-1], target, order) for order in self.finger_orders([idx])]
            way = next((w for w in ways if len(w) == 1 or self.valid(validity, w)), None)
            if way is None:
                return None
            path = np.concatenate([path, way[1:]])
        return path

    def fingers(self, phase: int, part: str, q: np.ndarray, arm: str, values: np.ndarray, situation: Situation) -> list[Piece]:
        """The hand's fingers moving to `values` (see finger_path), checked with the contact profile; PieceFailed naming
        what the all-at-once motion hits when no way is valid."""
        target = self.with_fingers(q, arm, values)
        if np.allclose(target, q):
            return []
        t = time.perf_counter()
        validity = self.finger_validity(q, target, situation)
        path = self.finger_path(q, arm, values, validity)
        self.stats[phase].seconds_contact += time.perf_counter() - t
        if path is None:
            raise PieceFailed(phase, part, lambda: f"collides ({_pairs(self.collisions(validity, np.stack([q, target])))})")
        return [Piece(phase, part, path, situation, arm)]

    def finger_collisions(self, q: np.ndarray, arm: str, values: np.ndarray, situation: Situation) -> list[tuple[str, str]]:
        """The colliding pairs of the fingers' motion from q to `values` all at once; empty when a way is valid (see
        finger_path)."""
        target = self.with_fingers(q, arm, values)
        if np.allclose(target, q):
            return []
        validity = self.finger_validity(q, target, situation)
        if self.finger_path(q, arm, values, validity) is not None:
            return []
        return self.collisions(validity, np.stack([q, target]))

    def finger_validity(self, q: np.ndarray, target: np.ndarray, situation: Situation) -> Validity:
        """The contact validity of finger motions from q to target: over the pairs the joints that differ change."""
        return self.validity(self.model(situation, q, np.flatnonzero(target != q)), self.contact_profile)

    def valid(self, validity: Validity, path: np.ndarray) -> bool:
        """validity.path_valid(path), checked once per plan: the pre-shape search checks the approach, shaping and
        closing of each candidate, and the pieces built from the one it keeps are the same motions."""
        return self._hit(validity, path) is None

    def collisions(self, validity: Validity, path: np.ndarray) -> list[tuple[str, str]]:
        """The colliding pairs where the path's check failed (none when valid): the pre-shape search opens the fingers
        they name."""
        return validity.colliding_pairs(self._hit(validity, path))

    def _hit(self, validity: Validity, path: np.ndarray) -> np.ndarray | None:
        """validity.path_hit(path), once per plan (see valid)."""
        key = (id(validity), path.tobytes())
        if key not in self.checked:
            self.checked[key] = validity.path_hit(path)
        return self.checked[key]

    def transit(self, phase: int, q_start: np.ndarray, q_goal: np.ndarray, situation: Situation, arm: str | None = None) -> Piece:
        """Torso and arms from q_start to q_goal (hands as at q_start), by the Super Graph (or RRTConnect: baseline);
        with `arm`, that arm alone, by RRTConnect (the graph's nodes are whole configurations), `part` 'arm away'."""
        robot = self.robot
        idx = self.transit_idx if arm is None else robot.arm_idx[arm]
        space = JointSpace.of(robot.lower, robot.upper, idx, q_start)
        if not space.holds(q_goal):
            raise ValueError("transit ends must agree on every joint outside the ones it moves")
        part = "transit" if arm is None else "arm away"
        full, near = self.transit_validities(self.model(situation, q_start, idx), q_start, q_goal)
        stats = self.stats[phase]
        checkers = {id(v.seg): v.seg for v in (full, near)}.values()  # one when no pair is fitted
        before = sum(c.checks for c in checkers)
        try:
            return self._transit(phase, part, q_start, q_goal, situation, space, full, near, arm)
        finally:
            stats.checks += sum(c.checks for c in checkers) - before

    def transit_validities(self, model: CollisionModel, q_start: np.ndarray, q_goal: np.ndarray) -> tuple[Validity, Validity]:
        """(full, near) of a transit between two configurations of a situation's model. `full`, for the whole transit,
        pads the pairs both ends hold close (a hand closed on the object holds its thumb near its own wrist) as the
        farther end allows: at the transit padding no configuration of the phase, no roadmap node, would be valid.
        `near`, for what touches an end, pads every pair either end holds close as the nearer end allows."""
        start, goal = (self.clearances(model, q) for q in (q_start, q_goal))
        closest = {pair: min(start.get(pair, np.inf), goal.get(pair, np.inf)) for pair in start.keys() | goal.keys()}
        held = {pair: max(start[pair], goal[pair]) for pair in start.keys() & goal.keys()}
        meter = self.meter(model)
        return (self.validity(model, self.transit_profile, meter.fitted_pairs(self.transit_profile, held)),
                self.validity(model, self.transit_profile, meter.fitted_pairs(self.transit_profile, closest)))

    def _transit(self, phase: int, part: str, q_start: np.ndarray, q_goal: np.ndarray, situation: Situation, space: JointSpace,
                 full: Validity, near: Validity, arm: str | None) -> Piece:
        """The transit's path, its ends checked first (see transit); what touches an end is checked `near` where it
        fails `full` (see Graded)."""
        for name, q in (("start", q_start), ("goal", q_goal)):
            if not near.state_valid(q):
                raise PieceFailed(phase, part, f"its {name} configuration collides ({_pairs(near.first_collision(q[None]))})")
        stats = self.stats[phase]
        if near.seg is not full.seg:  # dense only beside what the ends hold close
            near = Graded(full, near)
        try:
            if arm is not None:
                limit = dataclasses.replace(self.transit_params, rrt_motions=self.transit_params.reconnect_motions)
                path = rrt_transit(space, full, near, q_start, q_goal, limit, self.rng, stats)
            elif self.baseline:
                path = rrt_transit(space, full, near, q_start, q_goal, self.transit_params, self.rng, stats)
            else:  # a phase's queries share its RRT budget: once spent, they search the graph only
                left = max(0, self.p.phase_reconnections - stats.rrt_calls)
                params = dataclasses.replace(self.transit_params,
                                             max_reconnections=min(left, self.transit_params.max_reconnections))
                path = LazyTransit(self.graph, space, full.on("changed"), full, near, params, self.rng, stats).query(q_start, q_goal)
        except TransitFailed as exc:
            raise PieceFailed(phase, part, str(exc)) from exc
        t = time.perf_counter()
        gain = self.transit_params.shortcut_min_gain
        path = shortcut(shortcut_vertices(path, full, near, gain), full, near, self.rng, self.transit_params.shortcut_attempts, gain)
        stats.seconds_shortcut += time.perf_counter() - t
        return Piece(phase, part, path, situation)

    # ----- the task
    def plan(self, q_grasp: np.ndarray, q_exch: np.ndarray, q_place: np.ndarray, a: HandGrasp, b: HandGrasp) -> list[Piece]:
        """Every piece from q_initial to q_final through the double grasp (a: the picking hand, b: the placing hand; the
        same hand and grasp for a direct transfer, whose Carry takes the object to above its placement).

        The contact motions come first and every transit's ends are checked ready: a double grasp that cannot work
        fails in a fraction of a second, before any transit is searched. Where a transit fails, the next pre-grasp
        candidate of that hand is tried."""
        scene = self.scene
        oi, of = scene.object_initial, scene.object_final
        open_a, open_b = (self.open[self.robot.hand_idx[h.arm]] for h in (a, b))

        # exact grasps, so the object's pose is continuous where it changes hands: each hand holds it as its grasp and place
        # configurations do (within their IK tolerance of the listed grasp), and the exchange, in the air where both
        # arms have room, is refined to join them (a placement at the edge of the workspace, the torso at its limits,
        # cannot move its palm by the millimetres); a direct transfer: one hand holds it from the grasp to the placement
        direct = a.arm == b.arm
        g_a = np.linalg.inv(oi) @ self.palm(q_grasp, a.arm)
        if direct:
            g_b = g_a
            q_place = self.refine(q_place, b.arm, of @ g_b, None, 2, "place")
        else:
            g_b = np.linalg.inv(of) @ self.palm(q_place, b.arm)
            x = self.palm(q_exch, a.arm) @ np.linalg.inv(g_a)
            q_exch = self.refine(q_exch, b.arm, x @ g_b, a.arm, 1, "exchange")
        static_i, static_f = Situation(None, oi), Situation(None, of)
        held_a, held_b = Situation(a.arm, g_a), Situation(b.arm, g_b)
        tips_a = fingertip_geometries(self.cm, a.arm, a.touching)
        tips_b = fingertip_geometries(self.cm, b.arm, b.touching)
        support_i, support_f = self.supports(oi), self.supports(of)
        closing_a, closing_b = Situation(None, oi, tips_a), Situation(a.arm, g_a, tips_b)

        # Grasp: (pre-grasp, pre-shape + approach + closing) candidates
        def grasp(shaped: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, list[Piece]]:
            pre_a, approach = shaped[0], shaped[1][::-1]
            q_pre = self.with_fingers(approach[0], a.arm, open_a)
            out = [self.contact(0, "approach", approach, static_i, a.arm)]
            out = self.fingers(0, "pre-shape", q_pre, a.arm, pre_a, static_i) + out
            out += self.fingers(0, "closing", approach[-1], a.arm, a.fingers, closing_a)
            self.ready(q_pre, static_i, 0, "pre-grasp")
            return q_pre, out

        approaches = self.shaped(a, self.retreats(q_grasp, a.arm, None, True, 0, "pre-grasp"), static_i, closing_a)
        grasps = self.options(0, "pre-grasp", approaches, grasp)
        first_grasp = next(grasps)

        # Carry: the lift, (exchange pre-grasp, its approach and closing) candidates, the picking hand letting go and retreating
        def lift_off(offset: np.ndarray) -> tuple[np.ndarray, list[Piece], float]:
            lift = self.straight(self.with_fingers(q_grasp, a.arm, a.fingers), a.arm, offset, None, 1, "lift")
            piece = self.contact(1, "lift", lift, Situation(a.arm, g_a, (), support_i), a.arm)
            return lift[-1], [piece], self.ready(lift[-1], held_a, 1, "lift")

        q_lifted, lifted, _ = next(freest(self.options(1, "lift", iter(self.lifts(oi, q_grasp, a.arm, 1)), lift_off)))
        q_x = self.with_fingers(q_exch, a.arm, a.fingers)

        def exchange(shaped: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, list[Piece]]:
            pre_b, approach_b = shaped[0], shaped[1][::-1]
            q_pre_b = self.with_fingers(approach_b[0], b.arm, open_b)
            out = [self.contact(1, "approach", approach_b, held_a, b.arm)]
            out = self.fingers(1, "pre-shape", q_pre_b, b.arm, pre_b, held_a) + out
            out += self.fingers(1, "closing", approach_b[-1], b.arm, b.fingers, closing_b)
            self.ready(q_pre_b, held_a, 1, "exchange pre-grasp")
            return q_pre_b, out

        def leave(situation: Situation, after: Situation, phase: int, arm: str):
            def build(retreat: np.ndarray) -> list[Piece]:
                piece = self.contact(phase, "retreat", retreat, situation, arm)
                self.ready(retreat[-1], after, phase, "retreat")
                return [piece]
            return build

        if not direct:  # the placing hand's exchange pre-grasp, approach and closing; the picking hand letting go
            backoffs = self.retreats(q_x, b.arm, a.arm, False, 1, "exchange pre-grasp")
            exchanges = self.options(1, "exchange pre-grasp", self.shaped(b, backoffs, held_a, closing_b), exchange)
            first_exchange = next(exchanges)
            released = Situation(b.arm, g_b, tips_a)
            q_both = self.with_fingers(q_x, b.arm, b.fingers)
            let_a = self.letting_go(a, q_both, released)
            let_go_a = self.fingers(1, "opening", q_both, a.arm, let_a, released)

            q_let = self.with_fingers(q_both, a.arm, let_a)
            backing = itertools.chain(*self.retreats(q_let, a.arm, b.arm, False, 1, "retreat", leaving=True))
            retreat_a = next(self.options(1, "retreat", backing, leave(released, held_b, 1, a.arm)))

        # Place: (above the placement, set-down) candidates; the picking hand keeps its fingers as they let go until the
        # end (opened near the object, they hit it); in a direct transfer it is the hand that holds the object
        q_down = q_place if direct else self.with_fingers(q_place, a.arm, let_a)

        def set_down(offset: np.ndarray) -> tuple[np.ndarray, list[Piece], float]:
            lower = self.straight(q_down, b.arm, offset, None, 2, "above the placement")[::-1]
            piece = self.contact(2, "set-down", lower, Situation(b.arm, g_b, (), support_f), b.arm)
            return lower[0], [piece], self.ready(lower[0], held_b, 2, "above the placement")

        downs = freest(self.options(2, "set-down", iter(self.lifts(of, q_place, b.arm, 2)), set_down))
        first_down = next(downs)
        let_go = Situation(None, of, tips_b)
        let_b = self.letting_go(b, q_down, let_go)
        let_go_b = self.fingers(2, "opening", q_down, b.arm, let_b, let_go)
        q_let_b = self.with_fingers(q_down, b.arm, let_b)
        retreat_b = next(self.options(2, "retreat", itertools.chain(*self.retreats(q_let_b, b.arm, None, True, 2, "retreat")),
                                      leave(let_go, static_f, 2, b.arm)))

        # Rest: to the final configuration, then both hands open
        q_end = self.with_fingers(scene.q_final if direct else self.with_fingers(scene.q_final, a.arm, let_a), b.arm, let_b)
        self.ready(q_end, static_f, 3, "final configuration")
        opening = [] if np.allclose(q_end, scene.q_final) else [
            self.contact(3, "opening", np.stack([q_end, scene.q_final]), static_f, None)]

        # the transits: independent of each other now that every contact motion is made; run longest first as measured
        # (Carry's, Place's, Rest's, Grasp's, the arm away), so the last to finish is a short one
        to_grasp = (0, lambda: self.reach(0, scene.q_initial, grasps, first_grasp, static_i))
        to_rest = (3, lambda: [self.transit(3, retreat_b[-1].path[-1], q_end, static_f)])
        if direct:  # carried by the one hand from the lift to above the placement
            carry, rest, to_grasp = self.transits([(1, lambda: self.reach(1, q_lifted, downs, first_down, held_a)), to_rest,
                                                   to_grasp])
            raise_first([to_grasp, carry, rest])
            return to_grasp + lifted + carry + let_go_b + retreat_b + rest + opening
        # the picking arm alone away from the object, then the Place transit from where it went: both at once, the second
        # assuming the first reaches its first target; when it does not, the other targets are tried after them
        q_retreat = retreat_a[-1].path[-1]
        targets = self.away_targets(q_retreat, a.arm, q_place, held_b)
        start = targets[0] if targets else q_retreat
        carry, to_place, rest, to_grasp, away = self.transits([
            (1, lambda: self.reach(1, q_lifted, exchanges, first_exchange, held_a)),
            (2, lambda: self.reach(2, start, downs, first_down, held_b)), to_rest, to_grasp,
            (2, lambda: self.away(q_retreat, a.arm, targets[:1], held_b))])
        raise_first([to_grasp, carry])
        if targets and not away:
            away = self.away(q_retreat, a.arm, targets[1:], held_b)
            to_place = self.reach(2, (away or retreat_a)[-1].path[-1], downs, first_down, held_b)
        raise_first([to_place, rest])
        return to_grasp + lifted + carry + let_go_a + retreat_a + away + to_place + let_go_b + retreat_b + rest + opening

    def transits(self, jobs: list[tuple[int, Callable[[], list[Piece]]]]) -> list[list[Piece] | PieceFailed]:
        """The pieces of each (phase, job), or how it failed, in the order given; run in that order in forked workers
        (one per core). Each job has its own random stream and its own copy of the graph, so the result does not depend
        on how many run at once. Their figures join their phases'."""
        graph, rng, seeds = self.graph, self.rng, self.rng.integers(2**63, size=len(jobs))
        if not self.baseline:  # the roadmap's edge lengths, which every graph search weighs by: once, for every worker
            graph.weights(JointSpace.of(self.robot.lower, self.robot.upper, self.transit_idx, self.open))

        def run(i: int) -> tuple[list[Piece] | tuple[int, str, str], TransitStats]:
            phase, job = jobs[i]
            kept = self.stats[phase]
            self.rng, self.graph, self.stats[phase] = np.random.default_rng(seeds[i]), graph.copy(), TransitStats()
            try:
                return job(), self.stats[phase]
            except PieceFailed as exc:
                return (exc.phase, exc.part, exc.why), self.stats[phase]
            finally:
                self.rng, self.graph, self.stats[phase] = rng, graph, kept

        results = forked_map(run, range(len(jobs)))
        for (phase, _), (_, stats) in zip(jobs, results):
            for f in dataclasses.fields(stats):
                setattr(self.stats[phase], f.name, getattr(self.stats[phase], f.name) + getattr(stats, f.name))
        return [PieceFailed(*value) if isinstance(value, tuple) else value for value, _ in results]

    def away_targets(self, q: np.ndarray, arm: str, q_place: np.ndarray, situation: Situation) -> list[np.ndarray]:
        """Where the picking arm alone may go from its retreat, in order (see away): q with that arm as it is at the
        placement, else as it is at the end; those a transit can end at."""
        idx = self.robot.arm_idx[arm]
        out = []
        for there in (q_place, self.scene.q_final):
            target = q.copy()
            target[idx] = there[idx]
            try:
                self.ready(target, situation, 2, "arm away")
            except PieceFailed:
                continue
            out.append(target)
        return out

    def away(self, q: np.ndarray, arm: str, targets: list[np.ndarray], situation: Situation) -> list[Piece]:
        """The picking arm alone from its retreat to the first of `targets` it reaches (so the object, held by the
        other hand, is free of it before the Place transit begins, and that transit starts where the graph is valid);
        nothing when no motion is found quickly (the Place transit moves both arms)."""
        for target in targets:
            try:
                return [self.transit(2, q, target, situation, arm)]
            except PieceFailed:
                continue
        return []

    def lifts(self, pose: np.ndarray, q: np.ndarray, arm: str, phase: int) -> list[np.ndarray]:
        """World offsets to lift the object at `pose`, held by `arm` at q, off its support (reversed: to set it down
        there), freest first: up, then tilted 30°, 55° and 75° from the vertical in eight directions, each by the lift
        distance and twice as far, ordered by the clearance of the object and the hand from the obstacles at the
        offset's end (counted up to the transit padding: farther gains nothing, so the vertical lift comes first when
        it is free)."""
        dirs = [np.array([0.0, 0.0, 1.0])]
        for tilt in np.radians([30.0, 55.0, 75.0]):
            dirs += [np.array([np.sin(tilt) * np.cos(a), np.sin(tilt) * np.sin(a), np.cos(tilt)])
                     for a in np.radians(np.arange(0.0, 360.0, 45.0))]
        offsets = [scale * self.p.lift * d for scale in (1.0, 2.0) for d in dirs]
        gm = self.cm.geometry
        gd = pin.GeometryData(gm)
        pin.updateGeometryPlacements(self.robot.model, self.data, gm, gd, q)
        hand = [g for g in range(self.cm.n_robot_geoms) if self.cm.parts[g] == f"{arm}_hand"]
        bodies = [(self.shape, pose)] + [(gm.geometryObjects[g].geometry, gd.oMg[g].homogeneous) for g in hand]
        # obstacles whose bounding sphere stays farther than the padding from the bodies' at every offset cannot count
        centre, reach = _bounding_sphere(bodies)
        reach += 2.0 * self.p.lift + self.transit_profile.env_padding
        obstacles = [(shape, transform3s(ob.pose), world_aabb(shape, ob.pose)) for ob in self.scene.environment
                     for shape in [ob.coal_shape()] for c, r in [_bounding_sphere([(shape, ob.pose)])]
                     if np.linalg.norm(c - centre) < r + reach]
        spheres = [_bounding_sphere([body]) for body in bodies]
        req, res = coal.DistanceRequest(), coal.DistanceResult()

        def clearance(offset: np.ndarray, bound: np.ndarray) -> float:
            """The smallest distance, up to the padding, of a body from an obstacle at the offset: nearest first by
            `bound` (body, obstacle) a lower bound, skipping those whose bound is no nearer than the smallest so far."""
            out = self.transit_profile.env_padding
            for k in np.argsort(bound, axis=None, kind="stable"):
                b, o = np.unravel_index(k, bound.shape)
                if bound[b, o] >= out:
                    break
                shape, placed = bodies[b]
                moved = placed.copy()
                moved[:3, 3] += offset
                res.clear()
                out = min(out, coal.distance(shape, transform3s(moved), obstacles[o][0], obstacles[o][1], req, res))
            return out

        t0 = time.perf_counter()
        # per offset, body and obstacle: the distance from the body's bounding sphere to the obstacle's box
        centres = np.array([c for c, _ in spheres])[None, :, None] + np.array(offsets)[:, None, None]
        boxes = np.array([box for _, _, box in obstacles]).reshape(1, 1, -1, 2, 3)
        gap = np.maximum(np.maximum(boxes[..., 0, :] - centres, centres - boxes[..., 1, :]), 0.0)
        bounds = np.linalg.norm(gap, axis=-1) - np.array([r for _, r in spheres])[None, :, None]
        free = [clearance(o, bound) for o, bound in zip(offsets, bounds)]
        self.stats[phase].seconds_contact += time.perf_counter() - t0
        return [offsets[i] for i in sorted(range(len(offsets)), key=lambda i: -free[i])][: self.p.lift_candidates]

    def options(self, phase: int, part: str, candidates: Iterator, build) -> Iterator:
        """What `build` makes of each candidate for which it raises no PieceFailed, in order; past the last, the last
        failure is raised."""
        failure = None
        for candidate in candidates:
            try:
                yield build(candidate)
            except PieceFailed as exc:
                failure = exc
        raise failure or PieceFailed(phase, part, "the arm cannot back its hand off in a straight line")

    def reach(self, phase: int, q_start: np.ndarray, options: Iterator, option: tuple, situation: Situation) -> list[Piece]:
        """A transit from q_start to the first option ((where the transit ends, pieces from there, ...), in order) it
        can reach, then its pieces."""
        while True:
            q_to, after = option[:2]
            try:
                return [self.transit(phase, q_start, q_to, situation)] + after
            except PieceFailed as failed:
                try:
                    option = next(options)
                except (PieceFailed, StopIteration):
                    raise failed from None

    def supports(self, pose: np.ndarray) -> tuple[str, ...]:
        """Obstacles within 5 mm of the object at a placement: what it rests on."""
        out = []
        req, res = coal.DistanceRequest(), coal.DistanceResult()
        for ob in self.scene.environment:
            res.clear()
            if coal.distance(self.shape, transform3s(pose), ob.coal_shape(), transform3s(ob.pose), req, res) < 0.005:
                out.append(ob.name)
        return tuple(out)


FREE_ENOUGH = 0.75  # an end keeping three quarters of every transit padding is taken without looking further


def raise_first(results: list[list[Piece] | PieceFailed]) -> None:
    """Raise the first failure among the transits' results (given in phase order)."""
    failed = next((r for r in results if isinstance(r, PieceFailed)), None)
    if failed is not None:
        raise failed


def freest(options: Iterator[tuple]) -> Iterator[tuple]:
    """Options ((q, pieces, freedom) with freedom as `ready` gives it) in order while they are free enough, the others
    after them, freest first: a transit from a free end checks sparsely and leaves it easily."""
    held = []
    try:
        for option in options:
            if option[2] >= FREE_ENOUGH:
                yield option
            else:
                held.append(option)
    except PieceFailed:
        if not held:
            raise
    yield from sorted(held, key=lambda o: -o[2])


def _bounding_sphere(bodies: list[tuple[coal.CollisionGeometry, np.ndarray]]) -> tuple[np.ndarray, float]:
    """(centre, radius) of a sphere holding every (shape, world pose): meshes by their vertices (the robot's shapes are
    shared: they are only read), primitives by the bounding box they compute (each caller's own fresh shape)."""
    spheres = []
    for shape, placed in bodies:
        if hasattr(shape, "points") or hasattr(shape, "vertices"):
            pts = np.asarray(shape.points() if hasattr(shape, "points") else shape.vertices())
            mid = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
            radius = float(np.linalg.norm(pts - mid, axis=1).max())
        else:
            shape.computeLocalAABB()
            mid, radius = np.asarray(shape.aabb_center), float(shape.aabb_radius)
        spheres.append((placed[:3, :3] @ mid + placed[:3, 3], radius))
    centre = spheres[0][0]
    return centre, max(float(np.linalg.norm(c - centre)) + r for c, r in spheres)


def _pairs(pairs: list[tuple[str, str]], most: int = 3) -> str:
    """Colliding pairs in words, for failure messages."""
    text = ", ".join(f"{a} with {b}" for a, b in pairs[:most])
    return text + (f" and {len(pairs) - most} more pairs" if len(pairs) > most else "")
