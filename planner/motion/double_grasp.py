"""The motion of one double grasp, composed of stages the way a task constructor composes a task (paper V-B).

Grasp: transit to the pre-grasp (the picking hand backed off along its approach direction and raised,
fingers open), the fingers to their pre-shape, a straight approach, the fingers closing. Carry: the
object lifted off its support, transit to the exchange with the placing hand at its pre-grasp, its
approach and closing, then the picking hand letting go (its touching fingers open part way) and
retreating. Place: the picking arm alone away from the object (to where it is at the placement or at
the end), transit with the placing hand to near the placement, set down, let go, retreat. Rest:
transit to the final configuration, where both hands open fully (opened near the object, fingers
that wrapped around it would hit it).

The contact stages (contact.py) generate the states the transits connect, each candidate loop
(fallbacks.py) offering the next pre-grasp, pre-shape, lift or set-down where a piece fails. Every
contact motion is made, and every transit end checked ready, before any transit is searched: a double
grasp that cannot work is given up in a fraction of a second. Then the transit stages (transit_stage.py)
run at once (runner.py); where a transit fails, the next candidate end of that hand is tried.
"""
from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Iterator

import numpy as np

from planner.collision.situation import Situation, fingertip_geometries
from planner.model.task import Scene
from planner.motion.arm_motion import ArmMotions
from planner.motion.contact import ContactStages
from planner.motion.fallbacks import freest, options, raise_first, retreats
from planner.motion.fingers import Fingers
from planner.motion.graph import MotionGraph
from planner.motion.phase import Phase
from planner.motion.piece import TRANSIT_PARTS, HandGrasp, Piece, PieceFailed
from planner.motion.result import MotionParams
from planner.motion.runner import Job, run_transits
from planner.motion.smoothing import SmoothedRun, Smoother
from planner.motion.space import JointSpace
from planner.motion.transit import TransitStats
from planner.motion.transit_stage import TransitStage
from planner.motion.validities import Validities

GRASP, CARRY, PLACE, REST = Phase.GRASP, Phase.CARRY, Phase.PLACE, Phase.REST
Layout = list[int | list[Piece]]  # the motion in order: a transit job's index, or pieces made before the transits


class DoubleGraspPlanner:
    """Builds the pieces of one double grasp from its stages; keeps per-phase Table I figures in `stats`."""

    def __init__(self, scene: Scene, validities: Validities, graph: MotionGraph, params: MotionParams,
                 rng: np.random.Generator, baseline: bool, patient: bool = False):
        self.scene, self.validities, self.graph, self.p, self.rng, self.baseline = scene, validities, graph, params, rng, baseline
        self.patient = patient  # a transit that fails is searched again, longer (see patiently)
        self.stats = [TransitStats() for _ in Phase]
        self.arms = ArmMotions(scene.robot, validities.data, params, self.stats)
        self.hand = Fingers(validities.cm)
        self.contact = ContactStages(scene, validities, self.arms, self.hand, params, self.stats)
        robot = scene.robot
        vmax = np.minimum(np.asarray(robot.model.velocityLimit, float), params.max_velocity)
        self.smoother = Smoother(validities, vmax, np.full(robot.nq, params.max_acceleration), params.smooth_min_gain,
                                 params.smooth_attempts_per_s, params.smooth_checks_per_s, int(rng.integers(2**63)))
        self.smoothed: dict[tuple, SmoothedRun] = {}  # the runs the transit stages smoothed, by run_key,
        self.smoothing_seconds = 0.0  # and the seconds their workers spent on it

    def stage(self, phase: Phase, graph: MotionGraph | None = None, rng: np.random.Generator | None = None,
              stats: TransitStats | None = None) -> TransitStage:
        """A transit stage of the phase: on the plan's graph, random stream and figures, unless given its own."""
        return TransitStage(phase, self.validities, self.graph if graph is None else graph, self.rng if rng is None else rng,
                            self.stats[phase] if stats is None else stats, self.p, self.baseline)

    def transits(self, jobs: list[Job], layout: Layout) -> list[list[Piece] | PieceFailed]:
        """The jobs' pieces (or failures), run at once (see runner.py). `layout`: the motion in order, a job's place by
        its index, the pieces made before the transits as they are: each job's worker smooths the runs its pieces
        complete (Smoother.smooth_runs), kept in `smoothed`."""
        robot = self.scene.robot
        weights = None if self.baseline else JointSpace.of(robot.lower, robot.upper, self.contact.transit_idx, self.hand.open)

        def finish(i: int, pieces: list[Piece]) -> tuple[dict[tuple, SmoothedRun], float]:
            k = layout.index(i)
            start, end = k, k + 1
            while start > 0 and not isinstance(layout[start - 1], int):
                start -= 1
            while end < len(layout) and not isinstance(layout[end], int):
                end += 1
            before = [p for known in layout[start:k] for p in known]
            after = [p for known in layout[k + 1:end] for p in known]
            return self.smoother.smooth_runs(before + pieces + after, pieces, start > 0, end < len(layout))

        results = run_transits(jobs, self.stage, self.graph, self.rng, self.stats, weights, finish)
        for _, (smoothed, seconds) in (r for r in results if r[1] is not None):
            self.smoothed.update(smoothed)
            self.smoothing_seconds += seconds
        return [self.patiently(job, result) for job, (result, _) in zip(jobs, results)]

    def patiently(self, job: Job, result: list[Piece] | PieceFailed) -> list[Piece] | PieceFailed:
        """The job's result; for a patient planner, where its transit failed on the graph, the job run again here,
        RRTConnect given two more reconnections of the phase, each with the budget of a whole query of the baseline
        planner (`rrt_motions`, not `reconnect_motions`; the arm's move away too, not `away_motions`): a transit out of a
        tight spot (a wrist under a lamp) can need more than the quick search (strategies.py plans a sequence so when
        none moved without it)."""
        if not self.patient or self.baseline or not isinstance(result, PieceFailed) or result.part != TRANSIT_PARTS[0]:
            return result
        phase, run = job
        stats = self.stats[phase]
        patient = dataclasses.replace(self.p, reconnect_motions=self.p.rrt_motions, away_motions=self.p.rrt_motions,
                                      phase_reconnections=stats.rrt_calls + self.p.max_reconnections)
        try:
            return run(TransitStage(phase, self.validities, self.graph.copy(), self.rng, stats, patient, False))
        except PieceFailed:
            return result

    def away_targets(self, q: np.ndarray, arm: str, q_place: np.ndarray, situation: Situation) -> list[np.ndarray]:
        """Where the picking arm alone may go from its retreat, in order (see TransitStage.away): q with that arm as it
        is at the placement, else as it is at the end; those a transit can end at."""
        idx = self.scene.robot.arm_idx[arm]
        out = []
        for there in (q_place, self.scene.q_final):
            target = q.copy()
            target[idx] = there[idx]
            try:
                self.contact.ready(target, situation, PLACE, "arm away")
            except PieceFailed:
                continue
            out.append(target)
        return out

    def take(self, phase: Phase, g: HandGrasp, around: Situation, closing: Situation, label: str):
        """A hand's (pre-grasp, pre-shape + approach + closing) candidate builder, for a grasp at a placement and at the
        exchange alike: the hand opens fully at its pre-grasp."""
        c, hand = self.contact, self.hand
        opened = hand.open[self.scene.robot.hand_idx[g.arm]]

        def build(shaped: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, list[Piece]]:
            pre, approach = shaped[0], shaped[1][::-1]
            q_pre = hand.set(approach[0], g.arm, opened)
            out = [c.contact(phase, "approach", approach, around, g.arm)]
            out = c.fingers(phase, "pre-shape", q_pre, g.arm, pre, around) + out
            out += c.fingers(phase, "closing", approach[-1], g.arm, g.fingers, closing)
            c.ready(q_pre, around, phase, label)
            return q_pre, out
        return build

    def pick_up(self, phase: Phase, q_grasp: np.ndarray, g: HandGrasp, pose: np.ndarray) -> tuple[Iterator, tuple]:
        """(the candidates after the first, the first): a hand's (pre-grasp, pre-shape + approach + closing) onto the
        object resting at `pose`, the hand at its grasp at q_grasp."""
        static = Situation(None, pose)
        closing = Situation(None, pose, fingertip_geometries(self.validities.cm, g.arm, g.touching))
        approaches = self.contact.shaped(g, retreats(self.arms, q_grasp, g.arm, None, True, phase, "pre-grasp"), static, closing)
        grasps = options(phase, "pre-grasp", approaches, self.take(phase, g, static, closing, "pre-grasp"))
        return grasps, next(grasps)

    def lift(self, phase: Phase, q_grasp: np.ndarray, g: HandGrasp, palm_in_object: np.ndarray, pose: np.ndarray
             ) -> tuple[np.ndarray, list[Piece]]:
        """(where the lift ends, its piece): the object, held at q_grasp, lifted off its support at `pose`, freest first."""
        c, support = self.contact, self.contact.supports(pose)

        def lift_off(offset: np.ndarray) -> tuple[np.ndarray, list[Piece], float]:
            lift = self.arms.straight(self.hand.set(q_grasp, g.arm, g.fingers), g.arm, offset, None, phase, "lift")
            piece = c.contact(phase, "lift", lift, Situation(g.arm, palm_in_object, (), support), g.arm)
            return lift[-1], [piece], c.ready(lift[-1], Situation(g.arm, palm_in_object), phase, "lift")

        q_lifted, lifted, _ = next(freest(options(phase, "lift", iter(c.lifts(pose, q_grasp, g.arm, phase)), lift_off)))
        return q_lifted, lifted

    def set_downs(self, phase: Phase, q_down: np.ndarray, arm: str, palm_in_object: np.ndarray, pose: np.ndarray
                  ) -> tuple[Iterator, tuple]:
        """(the candidates after the first, the first): (above the placement, set-down) onto `pose`, the object held by
        `arm` at q_down there, freest first."""
        c, support = self.contact, self.contact.supports(pose)

        def set_down(offset: np.ndarray) -> tuple[np.ndarray, list[Piece], float]:
            lower = self.arms.straight(q_down, arm, offset, None, phase, "above the placement")[::-1]
            piece = c.contact(phase, "set-down", lower, Situation(arm, palm_in_object, (), support), arm)
            return lower[0], [piece], c.ready(lower[0], Situation(arm, palm_in_object), phase, "above the placement")

        downs = freest(options(phase, "set-down", iter(c.lifts(pose, q_down, arm, phase)), set_down))
        return downs, next(downs)

    def leave(self, situation: Situation, after: Situation, phase: Phase, arm: str):
        """A retreat candidate's builder: the hand backing off in `situation`, a transit ready to start in `after`."""
        def build(retreat: np.ndarray) -> list[Piece]:
            piece = self.contact.contact(phase, "retreat", retreat, situation, arm)
            self.contact.ready(retreat[-1], after, phase, "retreat")
            return [piece]
        return build

    def release(self, phase: Phase, q_down: np.ndarray, g: HandGrasp, pose: np.ndarray) -> tuple[np.ndarray, list[Piece]]:
        """(the hand's finger values, the pieces): a hand letting go of the object set down at `pose` (at q_down), then
        retreating."""
        c = self.contact
        let_go = Situation(None, pose, fingertip_geometries(self.validities.cm, g.arm, g.touching))
        let = c.letting_go(g, q_down, let_go)
        opening = c.fingers(phase, "opening", q_down, g.arm, let, let_go)
        q_let = self.hand.set(q_down, g.arm, let)
        backing = itertools.chain(*retreats(self.arms, q_let, g.arm, None, True, phase, "retreat"))
        return let, opening + next(options(phase, "retreat", backing, self.leave(let_go, Situation(None, pose), phase, g.arm)))

    def rest(self, fingers: dict[str, np.ndarray], pose: np.ndarray) -> tuple[np.ndarray, list[Piece]]:
        """(where the Rest transit ends, the hands opening there): q_final with each hand's fingers as they let go."""
        q_end = self.scene.q_final
        for arm, values in fingers.items():
            q_end = self.hand.set(q_end, arm, values)
        self.contact.ready(q_end, Situation(None, pose), REST, "final configuration")
        return q_end, [] if np.allclose(q_end, self.scene.q_final) else [
            self.contact.contact(REST, "hands open", np.stack([q_end, self.scene.q_final]), Situation(None, pose), None)]

    def plan(self, q_grasp: np.ndarray, q_exch: np.ndarray, q_place: np.ndarray, a: HandGrasp, b: HandGrasp) -> list[Piece]:
        """Every piece from q_initial to q_final through the double grasp (a: the picking hand, b: the placing hand; the
        same hand and grasp for a direct transfer, whose Carry takes the object to above its placement).

        The contact motions come first and every transit's ends are checked ready: a double grasp that cannot work
        fails in a fraction of a second, before any transit is searched. Where a transit fails, the next pre-grasp
        candidate of that hand is tried."""
        scene, c, arms, hand, cm = self.scene, self.contact, self.arms, self.hand, self.validities.cm
        oi, of = scene.object_initial, scene.object_final

        # exact grasps, so the object's pose is continuous where it changes hands and each hand holds it as its list
        # does (the double grasps' configurations hold their grasps to 2 mm, which puts a fingertip that much deeper):
        # the grasp and place configurations are refined to the listed grasps, and the exchange, in the air where both
        # arms have room, to join them; a direct transfer: one hand holds it from the grasp to the placement
        direct = a.arm == b.arm
        q_grasp = arms.refine(q_grasp, a.arm, oi @ a.palm_in_object, None, GRASP, "grasp")
        g_a = np.linalg.inv(oi) @ arms.palm(q_grasp, a.arm)
        g_b = g_a if direct else b.palm_in_object
        q_place = arms.refine(q_place, b.arm, of @ g_b, None, PLACE, "place")
        if not direct:
            g_b = np.linalg.inv(of) @ arms.palm(q_place, b.arm)
            x = arms.palm(q_exch, a.arm) @ np.linalg.inv(g_a)
            q_exch = arms.refine(q_exch, b.arm, x @ g_b, a.arm, CARRY, "exchange")
        static_i, static_f = Situation(None, oi), Situation(None, of)
        held_a, held_b = Situation(a.arm, g_a), Situation(b.arm, g_b)

        # Grasp: (pre-grasp, pre-shape + approach + closing) candidates; Carry: the lift
        grasps, first_grasp = self.pick_up(GRASP, q_grasp, a, oi)
        q_lifted, lifted = self.lift(CARRY, q_grasp, a, g_a, oi)
        q_x = hand.set(q_exch, a.arm, a.fingers)

        if not direct:  # the placing hand's exchange pre-grasp, approach and closing; the picking hand letting go
            tips_a, tips_b = fingertip_geometries(cm, a.arm, a.touching), fingertip_geometries(cm, b.arm, b.touching)
            closing_b = Situation(a.arm, g_a, tips_b)
            exchange = self.take(CARRY, b, held_a, closing_b, "exchange pre-grasp")
            backoffs = retreats(arms, q_x, b.arm, a.arm, False, CARRY, "exchange pre-grasp")
            exchanges = options(CARRY, "exchange pre-grasp", c.shaped(b, backoffs, held_a, closing_b), exchange)
            first_exchange = next(exchanges)
            released = Situation(b.arm, g_b, tips_a)
            q_both = hand.set(q_x, b.arm, b.fingers)
            let_a = c.letting_go(a, q_both, released)
            let_go_a = c.fingers(CARRY, "opening", q_both, a.arm, let_a, released)

            q_let = hand.set(q_both, a.arm, let_a)
            backing = itertools.chain(*retreats(arms, q_let, a.arm, b.arm, False, CARRY, "retreat", leaving=True))
            retreat_a = next(options(CARRY, "retreat", backing, self.leave(released, held_b, CARRY, a.arm)))

        # Place: (above the placement, set-down) candidates; the picking hand keeps its fingers as they let go until the
        # end (opened near the object, they hit it); in a direct transfer it is the hand that holds the object
        q_down = q_place if direct else hand.set(q_place, a.arm, let_a)
        downs, first_down = self.set_downs(PLACE, q_down, b.arm, g_b, of)
        let_b, released_b = self.release(PLACE, q_down, b, of)

        # Rest: to the final configuration, then both hands open
        q_end, opening = self.rest({b.arm: let_b} if direct else {a.arm: let_a, b.arm: let_b}, of)

        # the transits: independent of each other now that every contact motion is made; run longest first as measured
        # with the smoothing of their runs (Place's, Carry's, Rest's, Grasp's), so the last to finish is a short one
        to_grasp: Job = (GRASP, lambda s: s.reach(scene.q_initial, grasps, first_grasp, static_i))
        to_rest: Job = (REST, lambda s: [s.transit(released_b[-1].path[-1], q_end, static_f)])
        if direct:  # carried by the one hand from the lift to above the placement
            carry, rest, to_grasp = self.transits([(CARRY, lambda s: s.reach(q_lifted, downs, first_down, held_a)), to_rest,
                                                   to_grasp], [2, lifted, 0, released_b, 1, opening])
            raise_first([to_grasp, carry, rest])
            return to_grasp + lifted + carry + released_b + rest + opening
        # the picking arm alone away from the object, then the Place transit from where it went (from the retreat when
        # the arm found no way away)
        q_retreat = retreat_a[-1].path[-1]
        targets = self.away_targets(q_retreat, a.arm, q_place, held_b)

        def to_place(s: TransitStage) -> list[Piece]:
            away = s.away(q_retreat, a.arm, targets, held_b)
            return away + s.reach((away or retreat_a)[-1].path[-1], downs, first_down, held_b)

        place, carry, rest, to_grasp = self.transits([
            (PLACE, to_place), (CARRY, lambda s: s.reach(q_lifted, exchanges, first_exchange, held_a)), to_rest, to_grasp],
            [3, lifted, 1, let_go_a, retreat_a, 0, released_b, 2, opening])
        raise_first([to_grasp, carry, place, rest])
        return to_grasp + lifted + carry + let_go_a + retreat_a + place + released_b + rest + opening
