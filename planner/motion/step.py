"""The motion step (paper V-B): the whole task as one trajectory, the regrasp graph's sequences cheapest first (a
handover through a double grasp, a table handover or a same-hand regrasp; the `strategy` parameter says which may be
used: strategies.py).

Each sequence is planned by its stages (double_grasp.py, table_handover.py); the first whose every piece is valid is
smoothed and timed (smoothing.py) and sampled at a fixed rate (sampling.py). Measurements (seconds per phase and part) go to the
step's session record, never into the result, so the result depends on the inputs and the seed only.
"""
from __future__ import annotations

import contextlib
import gc
import time
from collections.abc import Iterator

import numpy as np
import pinocchio as pin

from planner.collision.checker import build_collision_model
from planner.collision.validity import Profile, transit_profile
from planner.core.steps import Progress, Step, StepContext, StepOutput, no_progress
from planner.grasping.grasp_list import GraspList
from planner.handover.double_grasps import DoubleGrasps
from planner.handover.grasp_configs import GraspConfigParams, GraspConfigs
from planner.model.task import Scene
from planner.motion import strategies
from planner.motion.double_grasp import DoubleGraspPlanner
from planner.motion.graph import MotionGraph
from planner.motion.phase import Phase
from planner.motion.piece import TRANSIT_PARTS, Piece
from planner.motion.result import PHASES, TABLE_PHASES, Motion, MotionParams
from planner.motion.sampling import sample
from planner.motion.smoothing import PASSES
from planner.motion.strategies import Attempt
from planner.motion.validities import Validities
from planner.regrasp.placements import Placements
from planner.roadmap.result import Roadmap

GRASP, CARRY, PLACE, REST, SET_DOWN, REGRASP = Phase


def contact_profile(p: MotionParams) -> Profile:
    """The paddings of the motions that touch the object (see validity.py)."""
    return Profile("contact", p.contact_env_padding, p.contact_env_clearance, 0.0, -p.contact_penetration, 0.0,
                   -p.contact_penetration, p.contact_coarse)


@contextlib.contextmanager
def collector_paused() -> Iterator[None]:
    """Python's cyclic garbage collector off inside (as it was on the way out): its full passes walk every object of the
    long-lived models, and in a forked worker the walk copies the pages the
    worker shares with its parent. A plan's few reference cycles are collected once it is done."""
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()


def plan_motion(scene: Scene, pick: GraspList, place: GraspList, dg: DoubleGrasps, roadmap: Roadmap, p: MotionParams,
                rng: np.random.Generator, progress: Progress = no_progress,
                configs: tuple[GraspConfigs, GraspConfigParams] | None = None, placements: Placements | None = None
                ) -> tuple[Motion, list[float]]:
    """(the motion, its stage seconds): the first strategy (strategies.py) whose whole motion is valid; `configs` (the
    grasp configurations and their parameters) and `placements` let the table handover be tried."""
    problem = p.problem()
    if problem:
        raise ValueError(f"motion.{problem}")
    with collector_paused():
        return _plan_motion(scene, pick, place, dg, roadmap, p, rng, progress, configs, placements)


def _plan_motion(scene: Scene, pick: GraspList, place: GraspList, dg: DoubleGrasps, roadmap: Roadmap, p: MotionParams,
                 rng: np.random.Generator, progress: Progress, configs: tuple[GraspConfigs, GraspConfigParams] | None,
                 placements: Placements | None) -> tuple[Motion, list[float]]:
    robot = scene.robot
    cm = build_collision_model(robot, scene.environment)
    transit = transit_profile(roadmap.resolution, p.transit_env_padding, p.transit_self_padding)
    contact = contact_profile(p)
    graph = MotionGraph(roadmap)

    def make(patient: bool) -> DoubleGraspPlanner:
        return DoubleGraspPlanner(scene, Validities(scene, cm, transit, contact), graph, p, rng, p.planner == "rrt", patient)

    attempt = strategies.plan_sequences(make, scene, pick, place, dg, configs, placements, p, rng, progress)
    resolution = {"transit": transit.describe(), "contact": contact.describe(),
                  "bound": "largest displacement of any robot or carried-object point, relative to what it may hit, between two "
                           "checks (coarse times that between two checks that found nothing within coarse times a padding's "
                           "margin over its clearance)"}
    alternatives = tuple(attempt.alternatives)
    if attempt.pieces is None:
        nq = robot.nq
        return Motion(p.planner, -1, attempt.tried, [], list(robot.spec.arm_names), resolution, attempt.stages, attempt.failure,
                      np.zeros(0), np.zeros((0, nq)), np.zeros(0, np.int8), np.zeros((0, 4, 4)), np.zeros(0, np.int8),
                      np.zeros(0, np.int8), np.zeros((0, 2, 3)), np.zeros(5, np.int64), tuple(robot.joint_names()),
                      alternatives=alternatives), attempt.seconds
    t = time.perf_counter()
    motion = _sampled(scene, attempt, p, resolution, alternatives)
    names = len(motion.phase_names)
    seconds = [x for s in attempt.planner.stats[:names] for x in (s.seconds_planning, s.seconds_validating, s.seconds_reconnecting,
                                                                   s.seconds_shortcut, s.seconds_contact)]
    seconds.append(time.perf_counter() - t + attempt.planner.smoothing_seconds)  # the smoothing in transit workers too
    seconds += attempt.seconds  # the search's stages come last in the result's stages too
    progress(1.0, f"{motion.duration:.1f} s of motion, {attempt.strategy} strategy, candidate {len(attempt.tried)}")
    return motion, seconds


def _sampled(scene: Scene, attempt: Attempt, p: MotionParams, resolution: dict, alternatives: tuple) -> Motion:
    """Smooth and sample the attempt's pieces (sampling.py), and pose the object and wrists at every sample."""
    robot, pieces, planner = scene.robot, attempt.pieces, attempt.planner
    arms = list(robot.spec.arm_names)
    out = sample(pieces, planner.smoother, 1.0 / p.rate, planner.smoothed)
    q = np.concatenate([scene.q_initial[None]] + out.q)
    qd = np.concatenate([np.zeros((1, robot.nq))] + out.v)  # at rest at the start
    qdd = np.concatenate([np.zeros((1, robot.nq)) if out.start_a is None else out.start_a] + out.a)
    kept = out.pieces
    owner = np.array([-1] + out.owner)
    data = robot.model.createData()
    palms = {a: robot.frame_id(robot.palm_frame(a)) for a in arms}
    mounts = [robot.frame_id(robot.spec.arm(a).hand.mount_frame) for a in arms]
    poses, wrists = [], []
    for k, qi in enumerate(q):
        pin.framesForwardKinematics(robot.model, data, qi)
        s = kept[owner[k]].situation if k else None
        palm = data.oMf[palms[s.holder]].homogeneous if s is not None and s.holder else None
        poses.append(scene.object_initial if s is None else s.object_pose(palm))
        wrists.append([data.oMf[m].translation.copy() for m in mounts])
    phase_arr = np.array([0] + [int(kept[i].phase) for i in owner[1:]], np.int8)  # stored as the phase's integer
    holder = [-1] + [arms.index(kept[i].situation.holder) if kept[i].situation.holder else -1 for i in owner[1:]]
    active = [-1] + [arms.index(kept[i].hand) if kept[i].hand else -1 for i in owner[1:]]
    ends = {i: int(np.flatnonzero(owner == i)[-1]) for i in set(owner[1:].tolist())}
    grasped, exchanged, placed = (next((ends[i] for i, pc in enumerate(kept) if (pc.phase, pc.part) in marks), None)
                                  for marks in (((GRASP, "closing"),), ((CARRY, "closing"), (REGRASP, "closing")),
                                                ((PLACE, "set-down"),)))
    key = [0, grasped, placed if exchanged is None else exchanged, placed, len(q) - 1]  # a direct transfer: no exchange
    names = PHASES if attempt.strategy == "handover" else TABLE_PHASES
    dt = 1.0 / p.rate
    t = np.arange(len(q)) * dt
    table = [_phase_row(i, planner.stats[i], q, phase_arr, dt, [pc for pc in pieces if pc.phase == i],
                        [run for ph, run in out.figures if ph == i], name) for i, name in enumerate(names)]
    stages = []
    for row in table:
        stages += [{"stage": f"{row['phase']}: transit planning", "count": row["nodes_planning"], "note": f"{row['searches']} searches"},
                   {"stage": f"{row['phase']}: transit validation", "count": row["edges_invalidated"], "note": "edges invalidated"},
                   {"stage": f"{row['phase']}: RRT reconnection", "count": row["nodes_validating"],
                    "note": f"nodes added by {row['rrt_calls']} RRTConnect calls"},
                   {"stage": f"{row['phase']}: shortcutting", "count": 0, "note": ""},
                   {"stage": f"{row['phase']}: approach, fingers, lift", "count": 0,
                    "note": f"path {row['path_length']:.2f} rad, {row['duration']:.2f} s"}]
    stages.append({"stage": "timing and sampling", "count": len(q),
                   "note": f"{sum(run.shortcuts for _, run in out.figures)} parabolic shortcuts, samples at {p.rate:g} Hz"})
    stages += attempt.stages  # after Table I's, whose seconds the workbench reads by position
    intermediate = () if attempt.intermediate is None else tuple(tuple(float(x) for x in row) for row in attempt.intermediate)
    return Motion(p.planner, attempt.used, attempt.tried, table, arms, resolution, stages, "", t, q, phase_arr, np.array(poses),
                  np.array(holder, np.int8), np.array(active, np.int8), np.array(wrists), np.array(key, np.int64),
                  tuple(robot.joint_names()), names, attempt.strategy, alternatives, intermediate, tuple(attempt.sequence), qd, qdd)


def _phase_row(i: int, st, q: np.ndarray, phase: np.ndarray, dt: float, pieces: list[Piece], smoothed: list, name: str) -> dict:
    """Table I's row of phase i: the transit figures, the phase's sampled path length, straight distance and duration,
    its transits' geometric length against the straight distance between their ends (before timing), and the smoothing
    of the runs that start in it (`smoothed`: their SmoothedRun): checks, and per pass (smoothing.PASSES) the shortcuts
    attempted, kept and the seconds they saved."""
    sel = np.flatnonzero(phase == i)
    seg = q[sel[0] - 1 if sel[0] else 0: sel[-1] + 1] if len(sel) else q[:0]
    transits = [pc.path for pc in pieces if pc.part in TRANSIT_PARTS]
    return {"phase": name, "nodes_planning": st.nodes_planning, "nodes_validating": st.nodes_validating,
            "edges_invalidated": st.edges_invalidated, "rrt_calls": st.rrt_calls, "searches": st.searches,
            "transit_checks": st.checks, "transit_pair_tests": st.pair_tests, "transit_pair_tests_rrt": st.pairs_rrt,
            "transit_pair_tests_shortcut": st.pairs_shortcut, "transit_pair_tests_away": st.pairs_away,
            "ends_alone": st.ends_alone, "smoothing_checks": sum(r.checks for r in smoothed),
            "smoothing_attempts": [int(sum(r.attempts[k] for r in smoothed)) for k in range(len(PASSES))],
            "smoothing_kept": [int(sum(r.kept[k] for r in smoothed)) for k in range(len(PASSES))],
            "smoothing_saved": [round(float(sum(r.saved[k] for r in smoothed)), 4) for k in range(len(PASSES))],
            "path_length": round(float(np.linalg.norm(np.diff(seg, axis=0), axis=1).sum()), 4),
            "straight_distance": round(float(np.linalg.norm(seg[-1] - seg[0])), 4) if len(seg) else 0.0,
            "transit_length": round(float(sum(np.linalg.norm(np.diff(x, axis=0), axis=1).sum() for x in transits)), 4),
            "transit_straight": round(float(sum(np.linalg.norm(x[-1] - x[0]) for x in transits)), 4),
            "duration": round(float(len(sel) * dt), 4)}


def run(ctx: StepContext) -> StepOutput:
    i = ctx.inputs
    motion, seconds = plan_motion(ctx.scene, i["pick_grasps"], i["place_grasps"], i["double_grasps"], i["roadmap"], ctx.params,
                                  ctx.rng, ctx.progress, (i["grasp_configs"], ctx.input_params["grasp_configs"]), i["placements"])
    return StepOutput(motion, tuple(seconds))


NAME = "motion"
STEP = Step(NAME, "the whole task's motion: Grasp, Carry, Place, Rest on the Super Graph (V-B)",
            ("pick_grasps", "place_grasps", "grasp_configs", "double_grasps", "roadmap", "placements"), MotionParams, Motion, run,
            retired=("smooth_attempts", "smooth_checks"))  # one budget for the whole motion: per run since stop 58
