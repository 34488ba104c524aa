"""The motion's strategies, tried in the order the `strategy` parameter gives (auto: the handover, then the table).

Handover: the double grasps best first (double_grasp.py), the paper's plan, or a direct transfer. Table: the picking
hand sets the object down at an intermediate placement both arms reach, and the placing hand takes it there
(table_handover.py): at the placements step's placements (planner/regrasp/placements.py), with configurations there
(planner/regrasp/table_configs.py) computed only when the table is tried. Each attempt says why every candidate
it tried failed, and, when none worked, the stage that removed them.
"""
from __future__ import annotations

import time
from collections import Counter
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
from planner.motion.piece import HandGrasp, Piece, PieceFailed
from planner.motion.result import MotionParams
from planner.motion.table_handover import plan_table
from planner.regrasp.placements import Placements
from planner.regrasp.table_configs import table_candidates


@dataclass
class Attempt:
    """What one strategy made: the pieces of the candidate that worked (None: none did), the planner that made them,
    why each candidate tried failed ('' for the one used), the failure naming the stage, the double grasp's rank
    (-1: none), the intermediate placement (a table handover), and the stages of the search with their seconds."""

    strategy: str
    tried: list[str] = field(default_factory=list)
    pieces: list[Piece] | None = None
    planner: DoubleGraspPlanner | None = None
    failure: str = ""
    used: int = -1
    intermediate: np.ndarray | None = None
    stages: list[dict] = field(default_factory=list)
    seconds: list[float] = field(default_factory=list)


def hand_grasp(grasps: GraspList, rank: int) -> HandGrasp:
    return HandGrasp(grasps.hand, grasps.hand_pose[rank], grasps.finger_q[rank],
                     [f for f, m in zip(grasps.fingers, grasps.contact_mask[rank]) if m])


def handover(make: Callable[[], DoubleGraspPlanner], pick: GraspList, place: GraspList, dg: DoubleGrasps, p: MotionParams,
             progress: Progress) -> Attempt:
    """The first double grasp, best first, whose whole motion is valid."""
    out = Attempt("handover")
    if dg.failure or not len(dg):
        out.failure = f"double grasps: {dg.failure or 'none to move with'}"
        return out
    count = min(len(dg), p.max_double_grasps)
    for k in range(count):
        progress(k / max(count, 1), f"double grasp {k + 1} of {count}")
        planner = make()
        try:
            pieces = planner.plan(dg.q_grasp[k], dg.q_exch[k], dg.q_place[k], hand_grasp(pick, int(dg.pick_rank[k])),
                                  hand_grasp(place, int(dg.place_rank[k])))
        except PieceFailed as exc:
            out.tried.append(str(exc))
            continue
        out.tried.append("")
        out.pieces, out.planner, out.used = pieces, planner, k
        return out
    out.failure = f"motion: no valid motion for any of the {count} double grasps tried: " + "; ".join(
        f"{i + 1}: {why}" for i, why in enumerate(out.tried))
    return out


def table(make: Callable[[], DoubleGraspPlanner], scene: Scene, pick: GraspList, place: GraspList,
          configs: tuple[GraspConfigs, GraspConfigParams] | None, placements: Placements | None, p: MotionParams,
          rng: np.random.Generator, progress: Progress) -> Attempt:
    """The first (intermediate placement, pick grasp, place grasp), best first, whose whole motion is valid: at most
    `table_candidates` tried, spread evenly over the first `table_placements` placements; a pick grasp whose Grasp or
    Set down failed at a placement is not tried there again with another place grasp (they change neither), nor a place
    grasp whose Carry, Place or Rest failed (carried from a placement that both arms reach to the final one, the next
    place grasp is likelier to get there than the next placement)."""
    out = Attempt("table")
    if configs is None or placements is None:
        out.failure = "grasp configurations and placements: not given to the motion planner"
        return out
    started = time.perf_counter()
    grasp_configs, params = configs
    if configs[0].picking_arm == configs[0].placing_arm:
        out.failure = f"arms: the {grasp_configs.picking_arm} arm picks and places, so no other hand takes the object"
        return out
    dropped: Counter = Counter()
    per_placement = -(-p.table_candidates // p.table_placements)  # tries spread over the placements
    failed_here: Counter = Counter()
    failed_before_regrasp: set[tuple[int, int]] = set()  # (placement, pick grasp) whose failure no place grasp changes
    failed_carrying: set[int] = set()  # place grasps that failed in Carry, Place or Rest
    for c in table_candidates(scene, pick, place, grasp_configs, params, placements, p.table_placements, dropped, rng):
        if len(out.tried) >= p.table_candidates:
            break
        if (failed_here[c.placement] >= per_placement or (c.placement, c.pick_rank) in failed_before_regrasp
                or c.place_rank in failed_carrying):
            continue
        progress(len(out.tried) / p.table_candidates, f"table handover {len(out.tried) + 1}: placement {c.placement + 1}")
        planner = make()
        try:
            pieces = plan_table(planner, c.q_grasp, c.q_set, c.q_take, c.q_place, hand_grasp(pick, c.pick_rank),
                                hand_grasp(place, c.place_rank), c.pose)
        except PieceFailed as exc:
            out.tried.append(f"placement {c.placement + 1} on {placements.support[c.placement]}, grasps {c.pick_rank + 1} and "
                             f"{c.place_rank + 1}: {exc}")
            failed_here[c.placement] += 1
            if exc.phase in (Phase.GRASP, Phase.SET_DOWN):
                failed_before_regrasp.add((c.placement, c.pick_rank))
            elif exc.phase != Phase.REGRASP:  # the place grasp's part, carried to the final placement and placed there
                failed_carrying.add(c.place_rank)
            continue
        out.tried.append("")
        out.pieces, out.planner, out.intermediate = pieces, planner, c.pose
        break
    why = "; ".join(f"{n} {reason}" for reason, n in sorted(dropped.items()))
    out.stages.append({"stage": "table handovers", "count": len(out.tried), "note": why or "every candidate tried"})
    out.seconds.append(time.perf_counter() - started)
    if out.pieces is None:
        counts = "; ".join(f"{s['stage']}: {s['count']}" for s in [*placements.stages, *out.stages])
        out.failure = (f"table: no valid motion for any of the {len(out.tried)} table handovers tried: " + "; ".join(
            f"{i + 1}: {w}" for i, w in enumerate(out.tried)) if out.tried else
            f"table: no intermediate placement where one hand sets the object down and the other takes it ({counts})")
    return out
