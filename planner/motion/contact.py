"""The contact stages: the short motions near the object that generate the states transits connect.

Approach (the hand's straight motion from its pre-grasp), pre-shape (the fingers shaped before it), close, lift,
set down, let go (the touching fingers open part way) and retreat, each checked with the contact profile in the
object's situation along it; `ready` checks that a transit can start or end where a stage leaves the robot. A
piece that cannot be made raises `PieceFailed` naming the phase and the part; the candidate loops (fallbacks.py)
try the next candidate.
"""
from __future__ import annotations

import time
from collections.abc import Iterator

import numpy as np

from planner.collision.offset_clearance import hand_bodies, obstacles_within, offset_clearances, supports
from planner.collision.situation import Situation
from planner.collision.validity import fits
from planner.model.task import Scene
from planner.motion.arm_motion import ArmMotions
from planner.motion.fallbacks import lift_offsets
from planner.motion.fingers import Fingers
from planner.motion.phase import Phase
from planner.motion.piece import HandGrasp, Piece, PieceFailed, pairs_text
from planner.motion.result import MotionParams
from planner.motion.transit import TransitStats
from planner.motion.transit_stage import transit_joints
from planner.motion.validities import Checked, Validities


class ContactStages:
    """The contact motions of one double grasp, checked with `validities`; their seconds go to the phase's `stats`."""

    def __init__(self, scene: Scene, validities: Validities, arms: ArmMotions, fingers: Fingers, params: MotionParams,
                 stats: list[TransitStats]):
        self.scene, self.validities, self.arms, self.hand, self.p, self.stats = scene, validities, arms, fingers, params, stats
        self.transit = validities.transit
        self.transit_idx = transit_joints(scene.robot)

    def ready(self, q: np.ndarray, situation: Situation, phase: Phase, part: str) -> float:
        """PieceFailed unless a transit can start or end at q in the situation: q is valid with the transit paddings
        fitted to its clearances, as a transit checks its ends (see validity.fits). Returns how free q is: the
        smallest share of a transit padding it keeps beyond the clearance guaranteed (1: as free as a roadmap node, so
        the transit's checks are as sparse as the roadmap's)."""
        t0 = time.perf_counter()
        checks = self.validities.of(situation, q, self.transit_idx)
        near = checks.clearances(q)
        have = checks.meter.by_kind(near)
        self.stats[phase].seconds_contact += time.perf_counter() - t0
        t = self.transit
        if not fits(t, have):
            end = lambda: checks.validity(t, checks.meter.fitted_pairs(t, near))  # noqa: E731
            raise PieceFailed(phase, part, lambda: f"ends too near something to start a transit "
                                                   f"({pairs_text(end().first_collision(q[None]))})")
        return min(1.0, *((have[k] - keep) / (pad - keep) for k, pad, keep in (
            ("env", t.env_padding, t.env_clearance), ("self", t.self_padding, t.self_clearance),
            ("object", t.object_padding, t.object_clearance))))

    def contact(self, phase: Phase, part: str, path: np.ndarray, situation: Situation, hand: str | None) -> Piece:
        """A short motion near the object (approach, lift, set-down, retreat, the last opening), checked with the
        contact profile."""
        t = time.perf_counter()
        checked = self.validities.of(situation, path[0], np.flatnonzero(np.ptp(path, axis=0) > 0)).checked(
            self.validities.contact)
        ok = checked.valid(path)
        self.stats[phase].seconds_contact += time.perf_counter() - t
        if not ok:
            raise PieceFailed(phase, part, lambda: f"collides ({pairs_text(checked.collisions(path))})")
        return Piece(phase, part, np.asarray(path), situation, hand)

    def fingers(self, phase: Phase, part: str, q: np.ndarray, arm: str, values: np.ndarray, situation: Situation) -> list[Piece]:
        """The hand's fingers moving to `values` (pre-shape, close, let go; see Fingers.path), checked with the contact
        profile; PieceFailed naming what the all-at-once motion hits when no way is valid."""
        target = self.hand.set(q, arm, values)
        if np.allclose(target, q):
            return []
        t = time.perf_counter()
        checked = self.finger_checks(q, target, situation)
        path = self.hand.path(q, arm, values, checked)
        self.stats[phase].seconds_contact += time.perf_counter() - t
        if path is None:
            raise PieceFailed(phase, part, lambda: f"collides ({pairs_text(checked.collisions(np.stack([q, target])))})")
        return [Piece(phase, part, path, situation, arm)]

    def finger_collisions(self, q: np.ndarray, arm: str, values: np.ndarray, situation: Situation) -> list[tuple[str, str]]:
        """The colliding pairs of the fingers' motion from q to `values` all at once; empty when a way is valid (see
        Fingers.path)."""
        target = self.hand.set(q, arm, values)
        if np.allclose(target, q):
            return []
        checked = self.finger_checks(q, target, situation)
        if self.hand.path(q, arm, values, checked) is not None:
            return []
        return checked.collisions(np.stack([q, target]))

    def finger_checks(self, q: np.ndarray, target: np.ndarray, situation: Situation) -> Checked:
        """The contact checks of finger motions from q to target: over the pairs the joints that differ change."""
        return self.validities.of(situation, q, np.flatnonzero(target != q)).checked(self.validities.contact)

    def shaped(self, grasp: HandGrasp, groups: list[Iterator[np.ndarray]], situation: Situation,
               closing: Situation) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """(pre-shape, approach path reversed with the fingers in it) candidates, group by group (see
        fallbacks.retreats): each retreat with the fingers shaped for it (see preshape)."""
        for group in groups:
            for path in group:
                pre = self.preshape(grasp, path, situation, closing)
                yield pre, np.array([self.hand.set(q, grasp.arm, pre) for q in path])

    def preshape(self, grasp: HandGrasp, path: np.ndarray, situation: Situation, closing: Situation) -> np.ndarray:
        """Finger values for shaping the open hand at the pre-grasp, approaching along a retreat path (reversed) and
        closing from there (in the `closing` situation, the touching fingertips allowed): open by the pre-shape fraction;
        a finger the shaping, the approach or the closing makes collide is tried wide open (its spreading joint too: an
        opposed thumb, opened only at its flexing joints, can reach across the object), then open by half, a fifth, not
        at all (see Fingers.per_finger)."""
        hand = self.hand
        open_hand = hand.open[self.scene.robot.hand_idx[grasp.arm]]
        levels = [hand.opened(grasp, self.p.preshape), open_hand] + [
            hand.opened(grasp, f) for f in (0.5 * self.p.preshape, 0.2 * self.p.preshape)] + [grasp.fingers]

        def collisions(pre: np.ndarray) -> list[tuple[str, str]]:
            approach = np.array([hand.set(q, grasp.arm, pre) for q in path])[::-1]
            checked = self.validities.of(situation, approach[0], np.flatnonzero(np.ptp(approach, axis=0) > 0)).checked(
                self.validities.contact)
            if not checked.valid(approach):
                return checked.collisions(approach)
            shaping = self.finger_collisions(hand.set(approach[0], grasp.arm, open_hand), grasp.arm, pre, situation)
            return shaping or self.finger_collisions(approach[-1], grasp.arm, grasp.fingers, closing)

        return hand.per_finger(grasp, levels, collisions)

    def letting_go(self, grasp: HandGrasp, q: np.ndarray, situation: Situation) -> np.ndarray:
        """Finger values letting go of the object held at q: the touching fingers open by the release fraction; one the
        opening makes collide (a thumb extending into the support) opens by half, a fifth, or stays (see
        Fingers.per_finger)."""
        levels = [self.hand.opened(grasp, f * self.p.release, True) for f in (1.0, 0.5, 0.2)] + [grasp.fingers]
        return self.hand.per_finger(grasp, levels, lambda values: self.finger_collisions(q, grasp.arm, values, situation))

    def lifts(self, pose: np.ndarray, q: np.ndarray, arm: str, phase: Phase) -> list[np.ndarray]:
        """World offsets to lift the object at `pose`, held by `arm` at q, off its support (reversed: to set it down
        there), freest first (see fallbacks.lift_offsets): ordered by the clearance of the object and the hand from the
        obstacles at the offset's end, counted up to the transit padding (farther gains nothing, so the vertical lift
        comes first when it is free); the first `lift_candidates`."""
        offsets = lift_offsets(self.p.lift)
        bodies = [(self.validities.shape, pose)] + hand_bodies(self.validities.cm, self.validities.data, q, arm)
        padding = self.transit.env_padding
        obstacles = obstacles_within(bodies, self.scene.environment, 2.0 * self.p.lift + padding)
        t0 = time.perf_counter()
        free = offset_clearances(bodies, obstacles, offsets, padding)
        self.stats[phase].seconds_contact += time.perf_counter() - t0
        return [offsets[i] for i in sorted(range(len(offsets)), key=lambda i: -free[i])][: self.p.lift_candidates]

    def supports(self, pose: np.ndarray) -> tuple[str, ...]:
        """The obstacles the object rests on at a placement."""
        return supports(self.validities.shape, pose, self.scene.environment)
