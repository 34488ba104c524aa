"""The motion's strategies: the regrasp graph's sequences (planner/regrasp/graph.py), cheapest first, each planned
until one moves.

Handover: a double grasp (double_grasp.py: the paper's plan, or a direct transfer). Table: the picking hand sets the
object down at an intermediate placement and the placing hand takes it there; regrasp: one arm picks and places,
setting the object down on the way and taking it again in another grasp (both table_handover.py). The `strategy`
parameter says which the graph may use (auto: all three, the handover first: the table and the regrasp are searched,
cheapest first, only when no double grasp moves). Each sequence tried and failed says why; a strategy with none tried
says the stage that removed it: ruled out before the search (no double grasp, no placement, the arms), no sequence in
the graph (the configurations at the placements), not tried (the handover moved), or dearer than the one that moved.
"""
from __future__ import annotations

import time
from collections import Counter, defaultdict
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from planner.core.steps import Progress
from planner.grasping.grasp_list import GraspList
from planner.handover.double_grasps import DoubleGrasps
from planner.handover.grasp_configs import GraspConfigParams, GraspConfigs
from planner.model.task import Scene
from planner.motion.double_grasp import DoubleGraspPlanner
from planner.motion.phase import Phase
from planner.motion.piece import TRANSIT_PARTS, HandGrasp, Piece, PieceFailed
from planner.motion.result import STRATEGIES, MotionParams
from planner.motion.table_handover import plan_table
from planner.regrasp.graph import HANDOVER, REGRASP, TABLE, CostModel, Search, Sequence
from planner.regrasp.placements import Placements
from planner.regrasp.task_graph import Limits, TaskGraph


@dataclass
class Attempt:
    """What the strategies made: the pieces of the sequence that worked (None: none did), the planner that made them,
    why each sequence tried failed ('' for the one used), the failure naming the stage per strategy, the double grasp's
    rank (-1: none), the intermediate placement, the sequence used, the other strategies with the stage that removed
    them, and the search's stages with their seconds."""

    strategy: str = ""
    tried: list[str] = field(default_factory=list)
    pieces: list[Piece] | None = None
    planner: DoubleGraspPlanner | None = None
    failure: str = ""
    used: int = -1
    intermediate: np.ndarray | None = None
    sequence: list[dict] = field(default_factory=list)
    alternatives: list[dict] = field(default_factory=list)
    stages: list[dict] = field(default_factory=list)
    seconds: list[float] = field(default_factory=list)
    given_up: Counter = field(default_factory=Counter)  # the transits of the sequences given up: checks, pair_tests, seconds


GIVEN_UP = "transits of the sequences given up"  # the stage that counts them (absent when the first sequence moved)


def hand_grasp(grasps: GraspList, rank: int) -> HandGrasp:
    return HandGrasp(grasps.hand, grasps.hand_pose[rank], grasps.finger_q[rank],
                     [f for f, m in zip(grasps.fingers, grasps.contact_mask[rank]) if m])


def ruled_out(dg: DoubleGrasps, configs: GraspConfigs | None, placements: Placements | None, allowed: tuple[str, ...]
              ) -> dict[str, str]:
    """strategy -> the stage that removes it before any search, for the strategies allowed."""
    out = {}
    if HANDOVER in allowed and (dg.failure or not len(dg)):
        out[HANDOVER] = f"double grasps: {dg.failure or 'none to move with'}"
    elif HANDOVER in allowed and configs is None:
        out[HANDOVER] = "grasp configurations: not given to the motion planner"
    for name in (TABLE, REGRASP):
        if name not in allowed:
            continue
        if configs is None or placements is None:
            out[name] = "grasp configurations and placements: not given to the motion planner"
        elif name == TABLE and configs.picking_arm == configs.placing_arm:
            out[name] = f"arms: the {configs.picking_arm} arm picks and places, so no other hand takes the object"
        elif name == REGRASP and configs.picking_arm != configs.placing_arm:
            out[name] = (f"arms: the {configs.picking_arm} arm picks and the {configs.placing_arm} arm places; a same-hand "
                         "regrasp needs one arm that does both")
        elif not len(placements) or not placements.reached[:, [placements.arms.index(configs.picking_arm),
                                                               placements.arms.index(configs.placing_arm)]].all(axis=1).any():
            counts = "; ".join(f"{s['stage']}: {s['count']}" for s in placements.stages)
            out[name] = f"placements: none that {'both arms reach' if name == TABLE else 'the arm reaches'} ({counts})"
    return out


class Skips:
    """Sequences not planned because one like them failed where they are the same: a pick grasp that failed before the
    other hand took the object is not tried again at that placement (the place grasp changes neither), a place grasp
    that failed carrying or placing not again (the next place grasp is likelier to get there than the next
    placement); at most `per_placement` motions per intermediate placement, so the tries spread over them."""

    def __init__(self, per_placement: int):
        self.per_placement = per_placement
        self.at: Counter = Counter()
        self.before_take: set[tuple[int, int]] = set()
        self.carrying: set[int] = set()

    def skip(self, seq: Sequence) -> bool:
        if seq.strategy == HANDOVER:
            return False
        k, r, s = seq.transitions[1].target.at, seq.transitions[0].target.grasp, seq.transitions[2].target.grasp
        return self.at[k] >= self.per_placement or (k, r) in self.before_take or s in self.carrying

    def failed(self, seq: Sequence, exc: PieceFailed) -> None:
        if seq.strategy == HANDOVER:
            return
        k, r, s = seq.transitions[1].target.at, seq.transitions[0].target.grasp, seq.transitions[2].target.grasp
        self.at[k] += 1
        if exc.phase in (Phase.GRASP, Phase.SET_DOWN):
            self.before_take.add((k, r))
        elif exc.phase != Phase.REGRASP:
            self.carrying.add(s)


def plan_sequences(make: Callable[[bool], DoubleGraspPlanner], scene: Scene, pick: GraspList, place: GraspList, dg: DoubleGrasps,
                   configs: tuple[GraspConfigs, GraspConfigParams] | None, placements: Placements | None, p: MotionParams,
                   rng: np.random.Generator, progress: Progress) -> Attempt:
    """The cheapest sequence of the regrasp graph whose whole motion is valid (see the module): at most
    `max_double_grasps` handovers and `table_candidates` table handovers or regrasps planned; when none moves, the first
    `patient_sequences` of them that failed at a transit are planned again by a patient planner (`make(True)`: see
    DoubleGraspPlanner.patiently), every contact motion of theirs having been made."""
    allowed = STRATEGIES[p.strategy]
    out = Attempt()
    removed = ruled_out(dg, configs[0] if configs else None, placements, allowed)
    started = time.perf_counter()
    graph = None
    if set(allowed) - set(removed):
        limits = Limits(p.max_double_grasps, p.table_placements, p.regrasp_grasps)
        # its own stream, spawned from the motion's without drawing from it: a handover draws as it did before the graph
        graph = TaskGraph(scene, pick, place, configs[0], configs[1], dg, placements, limits, set(allowed) - set(removed),
                          rng.spawn(1)[0])
    costs = CostModel(p.max_velocity, p.contact_seconds)
    search = Search(costs, graph.expand if graph else lambda node, path: [], scene.q_initial, scene.q_final,
                    graph.remaining if graph else lambda node: 0)
    budget = {HANDOVER: p.max_double_grasps, TABLE: p.table_candidates, REGRASP: p.table_candidates}
    tried: dict[str, list[str]] = defaultdict(list)
    skips = Skips(-(-p.table_candidates // p.table_placements))
    popped, chosen, planning = 0, None, 0.0
    done: set[str] = set()  # the handover, once its double grasps are tried

    stalled: list[Sequence] = []  # those that failed at a transit, in the order tried

    def attempt(seq: Sequence, patient: bool = False) -> bool:
        """Plan the sequence; whether it moved."""
        nonlocal chosen, planning
        name, again = seq.strategy, " again, patiently" if patient else ""
        progress(sum(map(len, tried.values())) / sum(budget[s] for s in allowed),
                 f"{name} sequence {len(tried[name]) + 1} ({seq.seconds:.1f} s estimated){again}")
        planner, t = make(patient), time.perf_counter()
        try:
            pieces = _plan(planner, seq, pick, place, dg, placements)
        except PieceFailed as exc:
            for st in planner.stats:
                out.given_up.update(checks=st.checks, pair_tests=st.pair_tests, seconds=st.transit_seconds)
            tried[name].append(f"{_describe(seq, placements)}{again}: {exc}")
            out.tried.append(tried[name][-1])
            skips.failed(seq, exc)
            if exc.part == TRANSIT_PARTS[0] and not patient:
                stalled.append(seq)
            return False
        finally:
            planning += time.perf_counter() - t
        out.tried.append("")
        chosen = seq
        out.pieces, out.planner, out.strategy, out.sequence, out.used = pieces, planner, name, seq.describe(), seq.transitions[1].rank
        if name != HANDOVER:
            out.intermediate = placements.pose[seq.transitions[1].target.at]
        return True

    turn = 0.0  # the estimate at which the strategy that moved had its turn
    if HANDOVER in allowed and HANDOVER not in removed:  # the paper's plan first: the others only when it fails
        if not any(attempt(Sequence.of(costs, scene.q_initial, graph.handover_edges(k))) for k in range(min(len(dg), budget[HANDOVER]))):
            done.add(HANDOVER)
    for seq in search.sequences() if chosen is None else ():
        popped += 1
        name, turn = seq.strategy, seq.seconds
        if all(s in done or len(tried[s]) >= budget[s] for s in allowed if s not in removed):
            break
        if name in done or len(tried[name]) >= budget[name] or skips.skip(seq):
            continue
        if attempt(seq):
            break
    for seq in stalled[: p.patient_sequences] if chosen is None else ():
        if attempt(seq, patient=True):
            break
    made = graph.made if graph else {}
    dropped = "; ".join(f"{n} {why}" for why, n in sorted(search.dropped.items()))
    searched = (f"sequences popped, cheapest first; {search.expanded} nodes expanded, {sum(v is not None for v in made.values())}"
                f" of {len(made)} configurations at intermediate placements found" + (f"; dropped: {dropped}" if dropped else ""))
    out.stages = [{"stage": "regrasp graph", "count": popped,
                   "note": "not searched: the handover moved" if chosen is not None and not popped else searched},
                  {"stage": "sequences planned", "count": len(out.tried),
                   "note": ", ".join(f"{len(tried[s]) + (s == out.strategy)} {s}" for s in allowed if s not in removed) or "none"}]
    out.seconds = [time.perf_counter() - started - planning, planning]
    if out.given_up["pair_tests"]:  # only where they did narrow-phase work: a motion planned at once, or whose sequences
        # given up failed in contact motions, keeps the stages it had (no stage counting 0, which a suite reads as emptied)
        out.stages.append({"stage": GIVEN_UP, "count": out.given_up["pair_tests"], "checks": out.given_up["checks"],
                           "note": f"narrow-phase pair tests, {out.given_up['checks']:,} checks (of the sequences planned)"})
        out.seconds.append(out.given_up["seconds"])
    for name in allowed:
        if name == out.strategy:
            continue
        if name in removed:
            why = removed[name]
        elif tried[name]:
            why = f"motion: no valid motion for any of the {len(tried[name])} sequences tried: " + "; ".join(
                f"{i + 1}: {w}" for i, w in enumerate(tried[name]))
        elif chosen is not None and chosen.strategy == HANDOVER:
            why = "not tried: the handover moved (it is tried first; the others only when it fails)"
        elif chosen is not None:
            why = f"dearer: none estimated below {turn:.1f} s, where the {chosen.strategy} strategy's turn came"
        else:
            why = f"regrasp graph: no sequence ({dropped or 'no configuration to move through'})"
        out.alternatives.append({"strategy": name, "failure": why})
    if chosen is None:
        out.failure = "; ".join(f"{a['strategy']} strategy: {a['failure']}" for a in out.alternatives)
    return out


def _plan(planner: DoubleGraspPlanner, seq: Sequence, pick: GraspList, place: GraspList, dg: DoubleGrasps,
          placements: Placements | None) -> list[Piece]:
    """Every piece of the sequence's motion."""
    t = seq.transitions
    if seq.strategy == HANDOVER:  # pick, hand over (or carry it: a direct transfer), place
        k = t[1].rank
        return planner.plan(dg.q_grasp[k], dg.q_exch[k], dg.q_place[k], hand_grasp(pick, int(dg.pick_rank[k])),
                            hand_grasp(place, int(dg.place_rank[k])))
    # pick, set down, take, carry, place
    return plan_table(planner, t[0].q, t[1].q, t[2].q, t[3].q, hand_grasp(pick, t[0].target.grasp),
                      hand_grasp(place, t[2].target.grasp), placements.pose[t[1].target.at])


def _describe(seq: Sequence, placements: Placements | None) -> str:
    t = seq.transitions
    if seq.strategy == HANDOVER:
        return f"double grasp {t[1].rank + 1} ({seq.seconds:.1f} s estimated)"
    k = t[1].target.at
    return (f"{seq.strategy} through placement {k + 1} on {placements.support[k]}, grasps {t[0].target.grasp + 1} and "
            f"{t[2].target.grasp + 1} ({seq.seconds:.1f} s estimated)")
