"""The four phases of the task (paper V-B) as pieces: transit motions on the Super Graph and contact motions.

Grasp: transit to the pre-grasp (the picking hand backed off along its approach direction and raised,
fingers open), the fingers to their pre-shape, a straight approach, the fingers closing. Carry: the
object lifted off its support, transit to the exchange with the placing hand at its pre-grasp, its
approach and closing, then the picking hand letting go (its touching fingers open part way) and
retreating. Place: transit with the placing hand to above the final placement, set down, let go,
retreat. Rest: transit to the final configuration, where both hands open fully (opened near the
object, fingers that wrapped around it would hit it).
Straight hand motions are IK waypoints of the arm and the torso; while the other hand holds the
object, its palm is held still by the same IK, so the object does not move. Every piece is checked
with the validity of its situation; a piece that fails raises `PieceFailed` naming the phase and the
part.
"""
from __future__ import annotations

import time
from collections.abc import Iterator
from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin

from ..arm_ik import ArmIK
from ..collision import CollisionModel
from ..geometry import coal_mesh, transform3s
from ..reach import approach_direction
from ..task import Scene
from .graph import MotionGraph
from .result import PHASES
from .situation import Situation, fingertip_geometries, situation_model
from .space import JointSpace
from .transit import LazyTransit, TransitFailed, TransitParams, TransitStats, rrt_transit, shortcut
from .validity import Profile, clearances, fitted, make_validity


@dataclass(frozen=True)
class Piece:
    """A checked polyline of one phase, with the object's situation along it."""

    phase: int
    part: str
    path: np.ndarray  # (k, nq), k >= 2
    situation: Situation
    hand: str | None = None  # the arm whose hand works near the object in a contact motion (None: transit)


class PieceFailed(Exception):
    def __init__(self, phase: int, part: str, why: str):
        super().__init__(f"{PHASES[phase]} phase, {part}: {why}")
        self.phase, self.part = phase, part


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
        self.data = self.robot.model.createData()
        self.iks: dict[tuple[str, ...], ArmIK] = {}  # one solver (and its scratch data) per set of arms
        self.stats = [TransitStats() for _ in PHASES]
        self.transit_params = TransitParams(params.connections, params.max_connections, params.max_searches, params.max_reconnections,
                                            params.reconnect_time, params.rrt_time, params.rrt_step, params.shortcut_attempts)
        robot = self.robot
        self.transit_idx = np.concatenate([robot.torso_idx] + [robot.arm_idx[a] for a in robot.spec.arm_names])
        self.open = robot.q_rest

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

    def retreats(self, q: np.ndarray, arm: str, keep: str | None, hover: bool, phase: int, part: str) -> Iterator[np.ndarray]:
        """Candidate IK polylines from q (the palm at a grasp) backing off along the approach direction (the pre-grasp
        distance, farther, nearer), then rising by the lift height when `hover` (the object rests on a support there;
        elsewhere rising is the last resort). Candidates the arm cannot follow are skipped."""
        up, back = np.array([0.0, 0.0, self.p.lift]), self.backoff(q, arm)
        rises = (1.0, 1.0, 2.0, 1.0) if hover else (0.0, 0.0, 0.0, 1.0)
        for scale, rise in zip((1.0, 1.7, 1.0, 0.5) if hover else (1.0, 1.7, 0.5, 1.0), rises):
            try:
                path = self.straight(q, arm, scale * back, keep, phase, part)
                if rise:
                    path = np.concatenate([path, self.straight(path[-1], arm, rise * up, keep, phase, part)[1:]])
            except PieceFailed:
                continue
            yield path

    def shaped(self, grasp: HandGrasp, retreats: Iterator[np.ndarray]) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """(pre-shape, approach path reversed with the fingers in it) candidates: each retreat with the fingers open by the
        pre-shape fraction, then half and a fifth as much (fingers sweep less where the hands are close)."""
        paths = list(retreats)
        for fraction in (self.p.preshape, 0.5 * self.p.preshape, 0.2 * self.p.preshape):
            pre = self.opened(grasp, fraction)
            for path in paths:
                yield pre, np.array([self.with_fingers(q, grasp.arm, pre) for q in path])

    def first(self, phase: int, part: str, candidates: Iterator, build) -> list[Piece]:
        """The pieces `build` makes of the first candidate for which it raises no PieceFailed."""
        failure = None
        for candidate in candidates:
            try:
                return build(candidate)
            except PieceFailed as exc:
                failure = exc
        raise failure or PieceFailed(phase, part, "the arm cannot back its hand off in a straight line")

    def ready(self, q: np.ndarray, situation: Situation, phase: int, part: str) -> None:
        """PieceFailed unless q keeps the transit clearances in the situation (so a transit can start or end there)."""
        model = self.model(situation, q, self.transit_idx)
        have = clearances(model, q, "moving")
        t = self.transit_profile
        if not (have["env"] > t.env_clearance and have["self"] > t.self_clearance and have["object"] > t.object_clearance):
            raise PieceFailed(phase, part, f"ends too near something to start a transit ({_pairs(self._near(model, q))})")

    def _near(self, model: CollisionModel, q: np.ndarray) -> list[tuple[str, str]]:
        return make_validity(model, self.transit_profile, "moving").first_collision(q[None])

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
        'changed', and 'moving' has the pairs the coordinates `moving` change."""
        moved = tuple(a for a in self.robot.spec.arm_names
                      if not np.allclose(q[self.robot.hand_idx[a]], self.open[self.robot.hand_idx[a]]))
        return situation_model(self.cm, self.shape, situation, moved, moving)

    def contact(self, phase: int, part: str, path: np.ndarray, situation: Situation, hand: str | None) -> Piece:
        """A short motion near the object, checked with the contact profile."""
        t = time.perf_counter()
        moving = np.flatnonzero(np.ptp(path, axis=0) > 0)
        validity = make_validity(self.model(situation, path[0], moving), self.contact_profile, "moving")
        ok = validity.path_valid(path)
        self.stats[phase].seconds_contact += time.perf_counter() - t
        if not ok:
            raise PieceFailed(phase, part, f"collides ({_pairs(validity.first_collision(path))})")
        return Piece(phase, part, np.asarray(path), situation, hand)

    def fingers(self, phase: int, part: str, q: np.ndarray, arm: str, values: np.ndarray, situation: Situation) -> list[Piece]:
        """The hand's fingers moving to `values` (nothing when they are there)."""
        target = self.with_fingers(q, arm, values)
        if np.allclose(target, q):
            return []
        return [self.contact(phase, part, np.stack([q, target]), situation, arm)]

    def transit(self, phase: int, q_start: np.ndarray, q_goal: np.ndarray, situation: Situation) -> Piece:
        """Torso and arms from q_start to q_goal (hands as at q_start), by the Super Graph (or RRTConnect: baseline)."""
        robot = self.robot
        space = JointSpace.of(robot.lower, robot.upper, self.transit_idx, q_start)
        if not space.holds(q_goal):
            raise ValueError("transit ends must agree on every joint outside the torso and arms")
        model = self.model(situation, q_start, self.transit_idx)
        ends = [clearances(model, q, "moving") for q in (q_start, q_goal)]
        profile = fitted(self.transit_profile, {k: min(e[k] for e in ends) for k in ends[0]})
        near = make_validity(model, profile, "moving")  # what touches the ends: as dense as they need
        full = near if profile == self.transit_profile else make_validity(model, self.transit_profile, "moving")
        for name, q in (("start", q_start), ("goal", q_goal)):
            if not near.state_valid(q):
                raise PieceFailed(phase, "transit", f"its {name} configuration collides ({_pairs(near.first_collision(q[None]))})")
        stats = self.stats[phase]
        try:
            if self.baseline:
                full = near  # a single query cannot tell the ends' neighbourhood from the rest: it checks as densely
                path = rrt_transit(space, near, q_start, q_goal, self.transit_params, self.rng, stats)
            else:
                path = LazyTransit(self.graph, space, full.on("changed"), full, near, self.transit_params, self.rng,
                                   stats).query(q_start, q_goal)
        except TransitFailed as exc:
            raise PieceFailed(phase, "transit", str(exc)) from exc
        t = time.perf_counter()
        path = shortcut(path, full, near, self.rng, self.transit_params.shortcut_attempts)
        stats.seconds_shortcut += time.perf_counter() - t
        return Piece(phase, "transit", path, situation)

    # ----- the task
    def plan(self, q_grasp: np.ndarray, q_exch: np.ndarray, q_place: np.ndarray, a: HandGrasp, b: HandGrasp) -> list[Piece]:
        """Every piece from q_initial to q_final through the double grasp (a: the picking hand, b: the placing hand)."""
        scene, p = self.scene, self.p
        oi, of = scene.object_initial, scene.object_final
        open_a, open_b = (self.open[self.robot.hand_idx[h.arm]] for h in (a, b))
        up = np.array([0.0, 0.0, p.lift])
        pieces: list[Piece] = []

        # exact grasps, so the object's pose is continuous where it changes hands
        g_a = np.linalg.inv(oi) @ self.palm(q_grasp, a.arm)
        x = self.palm(q_exch, a.arm) @ np.linalg.inv(g_a)
        q_exch = self.refine(q_exch, b.arm, x @ b.palm_in_object, a.arm, 1, "exchange")
        g_b = np.linalg.inv(x) @ self.palm(q_exch, b.arm)
        q_place = self.refine(q_place, b.arm, of @ g_b, None, 2, "place")
        static_i, static_f = Situation(None, oi), Situation(None, of)
        held_a, held_b = Situation(a.arm, g_a), Situation(b.arm, g_b)
        tips_a = fingertip_geometries(self.cm, a.arm, a.touching)
        tips_b = fingertip_geometries(self.cm, b.arm, b.touching)
        support_i, support_f = self.supports(oi), self.supports(of)

        # Grasp
        let_a = self.opened(a, p.release, True)

        def grasp(shaped: tuple[np.ndarray, np.ndarray]) -> list[Piece]:
            pre_a, approach = shaped[0], shaped[1][::-1]
            q_pre = self.with_fingers(approach[0], a.arm, open_a)
            out = [self.contact(0, "approach", approach, static_i, a.arm)]
            out = [self.transit(0, scene.q_initial, q_pre, static_i)] + self.fingers(0, "pre-shape", q_pre, a.arm, pre_a, static_i) + out
            return out + self.fingers(0, "closing", approach[-1], a.arm, a.fingers, Situation(None, oi, tips_a))

        pieces += self.first(0, "pre-grasp", self.shaped(a, self.retreats(q_grasp, a.arm, None, True, 0, "pre-grasp")), grasp)

        # Carry
        lift = self.straight(pieces[-1].path[-1], a.arm, up, None, 1, "lift")
        pieces.append(self.contact(1, "lift", lift, Situation(a.arm, g_a, (), support_i), a.arm))
        let_b = self.opened(b, p.release, True)
        q_x = self.with_fingers(q_exch, a.arm, a.fingers)

        def exchange(shaped: tuple[np.ndarray, np.ndarray]) -> list[Piece]:
            pre_b, approach_b = shaped[0], shaped[1][::-1]
            q_pre_b = self.with_fingers(approach_b[0], b.arm, open_b)
            out = [self.contact(1, "approach", approach_b, held_a, b.arm)]
            out = [self.transit(1, lift[-1], q_pre_b, held_a)] + self.fingers(1, "pre-shape", q_pre_b, b.arm, pre_b, held_a) + out
            return out + self.fingers(1, "closing", approach_b[-1], b.arm, b.fingers, Situation(a.arm, g_a, tips_b))

        pieces += self.first(1, "exchange pre-grasp", self.shaped(b, self.retreats(q_x, b.arm, a.arm, False, 1, "exchange pre-grasp")),
                             exchange)
        released = Situation(b.arm, g_b, tips_a)
        pieces += self.fingers(1, "opening", pieces[-1].path[-1], a.arm, let_a, released)

        def leave(situation: Situation, after: Situation, phase: int, arm: str):
            def build(retreat: np.ndarray) -> list[Piece]:
                piece = self.contact(phase, "retreat", retreat, situation, arm)
                self.ready(retreat[-1], after, phase, "retreat")
                return [piece]
            return build

        pieces += self.first(1, "retreat", self.retreats(pieces[-1].path[-1], a.arm, b.arm, False, 1, "retreat"),
                             leave(released, held_b, 1, a.arm))

        # Place (the picking hand keeps its fingers as they let go until the end: opened near the object, they hit it)
        q_down = self.with_fingers(q_place, a.arm, let_a)
        lower = self.straight(q_down, b.arm, up, None, 2, "above the placement")[::-1]
        pieces.append(self.transit(2, pieces[-1].path[-1], lower[0], held_b))
        pieces.append(self.contact(2, "set-down", lower, Situation(b.arm, g_b, (), support_f), b.arm))
        let_go = Situation(None, of, tips_b)
        pieces += self.fingers(2, "opening", lower[-1], b.arm, let_b, let_go)
        pieces += self.first(2, "retreat", self.retreats(pieces[-1].path[-1], b.arm, None, True, 2, "retreat"),
                             leave(let_go, static_f, 2, b.arm))

        # Rest: to the final configuration, then both hands open
        q_end = self.with_fingers(self.with_fingers(scene.q_final, a.arm, let_a), b.arm, let_b)
        pieces.append(self.transit(3, pieces[-1].path[-1], q_end, static_f))
        if not np.allclose(q_end, scene.q_final):
            pieces.append(self.contact(3, "opening", np.stack([q_end, scene.q_final]), static_f, None))
        return pieces

    def supports(self, pose: np.ndarray) -> tuple[str, ...]:
        """Obstacles within 5 mm of the object at a placement: what it rests on."""
        out = []
        req, res = coal.DistanceRequest(), coal.DistanceResult()
        for ob in self.scene.environment:
            res.clear()
            if coal.distance(self.shape, transform3s(pose), ob.coal_shape(), transform3s(ob.pose), req, res) < 0.005:
                out.append(ob.name)
        return tuple(out)


def _pairs(pairs: list[tuple[str, str]], most: int = 3) -> str:
    """Colliding pairs in words, for failure messages."""
    text = ", ".join(f"{a} with {b}" for a, b in pairs[:most])
    return text + (f" and {len(pairs) - most} more pairs" if len(pairs) > most else "")
