"""The transit stage of one phase: torso and arms between two states the contact stages made, by the Super Graph
(transit.py; RRTConnect alone for the baseline), then shortcut.

A stage has its own random stream, graph and figures: the transits of the phases run at once, each in its own
stage (see runner.py), so a result does not depend on how many run together.
"""
from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Iterator

import numpy as np

from planner.collision.situation import Situation
from planner.collision.validity import Graded, Validity
from planner.model.robot import Robot
from planner.motion.graph import MotionGraph
from planner.motion.phase import Phase
from planner.motion.piece import TRANSIT_PARTS, Piece, PieceFailed, pairs_text
from planner.motion.result import MotionParams
from planner.motion.space import JointSpace
from planner.motion.transit import (
    LazyTransit,
    TransitFailed,
    TransitParams,
    TransitStats,
    kept_detours,
    rrt_transit,
    shortcut,
    shortcut_vertices,
)
from planner.motion.validities import Validities


def transit_joints(robot: Robot) -> np.ndarray:
    """The configuration indices a transit moves: the torso and every arm (the hands stay as they are)."""
    return np.concatenate([robot.torso_idx] + [robot.arm_idx[a] for a in robot.spec.arm_names])


class TransitStage:
    """Transits of one phase on `graph` (its own copy, or the plan's), drawing from `rng`, counting into `stats`."""

    def __init__(self, phase: Phase, validities: Validities, graph: MotionGraph, rng: np.random.Generator, stats: TransitStats,
                 params: MotionParams, baseline: bool):
        self.phase, self.validities, self.graph, self.rng, self.stats = phase, validities, graph, rng, stats
        self.p, self.baseline = params, baseline
        self.transit_params = TransitParams.of(params)
        self.robot = validities.robot
        self.transit_idx = transit_joints(self.robot)

    def transit(self, q_start: np.ndarray, q_goal: np.ndarray, situation: Situation, arm: str | None = None) -> Piece:
        """Torso and arms from q_start to q_goal (hands as at q_start), by the Super Graph (or RRTConnect: baseline);
        with `arm`, that arm alone, by RRTConnect (the graph's nodes are whole configurations), `part` 'arm away'."""
        robot = self.robot
        idx = self.transit_idx if arm is None else robot.arm_idx[arm]
        space = JointSpace.of(robot.lower, robot.upper, idx, q_start)
        if not space.holds(q_goal):
            raise ValueError("transit ends must agree on every joint outside the ones it moves")
        part = TRANSIT_PARTS[0] if arm is None else TRANSIT_PARTS[1]
        full, near = self.validities.of(situation, q_start, idx).transit_validities(q_start, q_goal)
        checkers = [full.seg] if near.seg is full.seg else [full.seg, near.seg]  # one when no pair is fitted
        scratch = list({id(c.checker): c.checker for c in checkers}.values())  # the situation's, shared by both
        def pairs() -> int:
            return sum(c.pair_tests for c in scratch)

        before = sum(c.checks for c in checkers), pairs()
        try:
            return self._transit(part, q_start, q_goal, situation, space, full, near, arm, pairs)
        finally:
            self.stats.checks += sum(c.checks for c in checkers) - before[0]
            self.stats.pair_tests += pairs() - before[1]
            if arm is not None:  # counted apart, whole: the same work for either planner
                self.stats.pairs_away += pairs() - before[1]

    def _transit(self, part: str, q_start: np.ndarray, q_goal: np.ndarray, situation: Situation, space: JointSpace,
                 full: Validity, near: Validity, arm: str | None, pairs: Callable[[], int]) -> Piece:
        """The transit's path, its ends checked first (see transit); what touches an end is checked `near` where it
        fails `full` (see Graded). `pairs`: the pair tests the transit's checkers have made (counted per part; an arm's
        alone, whole, by `transit`)."""
        phase, stats, tp = self.phase, self.stats, self.transit_params
        for name, q in (("start", q_start), ("goal", q_goal)):
            if not near.state_valid(q):
                raise PieceFailed(phase, part, f"its {name} configuration collides ({pairs_text(near.first_collision(q[None]))})")
        if near.seg is not full.seg:  # dense only beside what the ends hold close
            near = Graded(full, near)
        detours = None  # a graph path's segments RRTConnect made (see shortcut_vertices)
        spent = ""  # why a graph query may not reconnect (told with its failure)
        try:
            if arm is not None or self.baseline:  # one arm: its own budget
                motions = tp.away_motions if arm is not None else tp.rrt_motions
                before = pairs()
                try:
                    path = rrt_transit(space, full, near, q_start, q_goal, dataclasses.replace(tp, rrt_motions=motions),
                                       self.rng, stats)
                finally:
                    stats.pairs_rrt += (pairs() - before) if arm is None else 0
            else:  # a phase's queries share its RRT budget: once spent, they search the graph only
                left = max(0, self.p.phase_reconnections - stats.rrt_calls)
                if left == 0 < tp.max_reconnections:
                    n = self.p.phase_reconnections
                    spent = (" (motion.phase_reconnections is 0: no RRTConnect reconnection)" if n == 0 else
                             f" (the phase's {n} RRTConnect call{'s' if n > 1 else ''} (motion.phase_reconnections) went to its "
                             "earlier transits)")
                params = dataclasses.replace(tp, max_reconnections=min(left, tp.max_reconnections))
                query = LazyTransit(self.graph, space, full.on("changed"), full, near, params, self.rng, stats, pairs)
                path = query.query(q_start, q_goal)
                detours = query.detours
        except TransitFailed as exc:
            raise PieceFailed(phase, part, str(exc) + spent) from exc
        t, shortcut_before = time.perf_counter(), pairs()
        gain = tp.shortcut_min_gain
        longest = np.inf if detours is None else tp.graph_shortcut_length  # a graph path: see shortcut_vertices
        greedy = shortcut_vertices(path, full, near, gain, longest, detours)
        kept = None if detours is None else kept_detours(path, detours, greedy)
        path = shortcut(greedy, full, near, self.rng, tp.shortcut_attempts, gain, longest, kept)
        stats.seconds_shortcut += time.perf_counter() - t
        stats.pairs_shortcut += (pairs() - shortcut_before) if arm is None else 0
        return Piece(phase, part, path, situation)

    def reach(self, q_start: np.ndarray, options: Iterator, option: tuple, situation: Situation) -> list[Piece]:
        """A transit from q_start to the first option ((where the transit ends, pieces from there, ...), in order) it
        can reach, then its pieces: the next candidate end is tried where a transit fails."""
        while True:
            q_to, after = option[:2]
            try:
                return [self.transit(q_start, q_to, situation)] + after
            except PieceFailed as failed:
                try:
                    option = next(options)
                except (PieceFailed, StopIteration):
                    raise failed from None

    def away(self, q: np.ndarray, arm: str, targets: list[np.ndarray], situation: Situation) -> list[Piece]:
        """The picking arm alone from its retreat to the first of `targets` it reaches (so the object, held by the
        other hand, is free of it before the Place transit begins, and that transit starts where the graph is valid);
        nothing when no motion is found quickly (the Place transit moves both arms)."""
        for target in targets:
            try:
                return [self.transit(q, target, situation, arm)]
            except PieceFailed:
                continue
        return []
