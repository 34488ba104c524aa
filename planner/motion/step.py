"""The motion step (paper V-B): the whole task as one trajectory, the double grasps tried best first.

Each double grasp is planned by its stages (double_grasp.py); the first whose every piece is valid is
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
from planner.model.task import Scene
from planner.motion.double_grasp import DoubleGraspPlanner
from planner.motion.graph import MotionGraph
from planner.motion.piece import TRANSIT_PARTS, HandGrasp, Piece, PieceFailed
from planner.motion.result import PHASES, Motion, MotionParams
from planner.motion.sampling import sample
from planner.motion.smoothing import Smoother
from planner.motion.validities import Validities
from planner.roadmap.result import Roadmap


def contact_profile(p: MotionParams) -> Profile:
    """The paddings of the motions that touch the object (see validity.py)."""
    return Profile("contact", p.contact_env_padding, p.contact_env_clearance, 0.0, -p.contact_penetration, 0.0,
                   -p.contact_penetration, p.contact_coarse)


def hand_grasp(grasps: GraspList, rank: int) -> HandGrasp:
    return HandGrasp(grasps.hand, grasps.hand_pose[rank], grasps.finger_q[rank],
                     [f for f, m in zip(grasps.fingers, grasps.contact_mask[rank]) if m])


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
                rng: np.random.Generator, progress: Progress = no_progress) -> tuple[Motion, list[float]]:
    """(the motion, its stage seconds): the first double grasp, best first, whose whole motion is valid."""
    problem = p.problem()
    if problem:
        raise ValueError(f"motion.{problem}")
    with collector_paused():
        return _plan_motion(scene, pick, place, dg, roadmap, p, rng, progress)


def _plan_motion(scene: Scene, pick: GraspList, place: GraspList, dg: DoubleGrasps, roadmap: Roadmap, p: MotionParams,
                 rng: np.random.Generator, progress: Progress) -> tuple[Motion, list[float]]:
    robot = scene.robot
    cm = build_collision_model(robot, scene.environment)
    transit = transit_profile(roadmap.resolution, p.transit_env_padding, p.transit_self_padding)
    contact = contact_profile(p)
    graph = MotionGraph(roadmap)
    tried: list[str] = []
    pieces: list[Piece] | None = None
    planner = None
    count = min(len(dg), p.max_double_grasps)
    for k in range(count):
        progress(k / max(count, 1), f"double grasp {k + 1} of {count}")
        planner = DoubleGraspPlanner(scene, Validities(scene, cm, transit, contact), graph, p, rng, baseline=p.planner == "rrt")
        try:
            pieces = planner.plan(dg.q_grasp[k], dg.q_exch[k], dg.q_place[k], hand_grasp(pick, int(dg.pick_rank[k])),
                                  hand_grasp(place, int(dg.place_rank[k])))
        except PieceFailed as exc:
            tried.append(str(exc))
            continue
        tried.append("")
        break
    resolution = {"transit": transit.describe(), "contact": contact.describe(),
                  "bound": "largest displacement of any robot or carried-object point, relative to what it may hit, between two "
                           "checks (coarse times that between two checks that found nothing within coarse times a padding's "
                           "margin over its clearance)"}
    if pieces is None:
        failure = f"no valid motion for any of the {count} double grasps tried: " + "; ".join(
            f"{i + 1}: {why}" for i, why in enumerate(tried)) if count else "no double grasp to move with"
        return _empty(p, robot, tried, resolution, failure), []
    t = time.perf_counter()
    motion = _sampled(scene, pieces, p, tried, resolution, planner, rng)
    seconds = [x for s in planner.stats for x in (s.seconds_planning, s.seconds_validating, s.seconds_reconnecting, s.seconds_shortcut,
                                                   s.seconds_contact)] + [time.perf_counter() - t]
    progress(1.0, f"{motion.duration:.1f} s of motion with double grasp {len(tried)}")
    return motion, seconds


def _empty(p: MotionParams, robot, tried: list, resolution: dict, failure: str) -> Motion:
    nq = robot.nq
    return Motion(p.planner, -1, tried, [], list(robot.spec.arm_names), resolution, [], failure, np.zeros(0), np.zeros((0, nq)),
                  np.zeros(0, np.int8), np.zeros((0, 4, 4)), np.zeros(0, np.int8), np.zeros(0, np.int8), np.zeros((0, 2, 3)),
                  np.zeros(5, np.int64), tuple(robot.joint_names()))


def _sampled(scene: Scene, pieces: list[Piece], p: MotionParams, tried: list, resolution: dict, planner: DoubleGraspPlanner,
             rng: np.random.Generator) -> Motion:
    """Smooth and sample the pieces (sampling.py), and pose the object and wrists at every sample."""
    robot = scene.robot
    arms = list(robot.spec.arm_names)
    vmax = np.minimum(np.asarray(robot.model.velocityLimit, float), p.max_velocity)
    smoother = Smoother(planner.validities, vmax, np.full(robot.nq, p.max_acceleration), p.smooth_min_gain)
    out = sample(pieces, smoother, rng, 1.0 / p.rate, p.smooth_attempts, p.smooth_checks)
    q = np.concatenate([scene.q_initial[None]] + out.q)
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
    grasped, exchanged, placed = (next((ends[i] for i, pc in enumerate(kept) if (pc.phase, pc.part) == mark), None)
                                  for mark in ((0, "closing"), (1, "closing"), (2, "set-down")))
    key = [0, grasped, placed if exchanged is None else exchanged, placed, len(q) - 1]  # a direct transfer: no exchange
    dt = 1.0 / p.rate
    t = np.arange(len(q)) * dt
    table = [_phase_row(i, st, q, phase_arr, dt, [pc for pc in pieces if pc.phase == i],
                        sum(c for ph, c, _ in out.figures if ph == i)) for i, st in enumerate(planner.stats)]
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
                   "note": f"{sum(k for _, _, k in out.figures)} parabolic shortcuts, samples at {p.rate:g} Hz"})
    return Motion(p.planner, len(tried) - 1, tried, table, arms, resolution, stages, "", t, q, phase_arr, np.array(poses),
                  np.array(holder, np.int8), np.array(active, np.int8), np.array(wrists), np.array(key, np.int64),
                  tuple(robot.joint_names()))


def _phase_row(i: int, st, q: np.ndarray, phase: np.ndarray, dt: float, pieces: list[Piece], smoothing_checks: int) -> dict:
    """Table I's row of phase i: the transit figures, the phase's sampled path length, straight distance and duration,
    and its transits' geometric length against the straight distance between their ends (before timing)."""
    sel = np.flatnonzero(phase == i)
    seg = q[sel[0] - 1 if sel[0] else 0: sel[-1] + 1] if len(sel) else q[:0]
    transits = [pc.path for pc in pieces if pc.part in TRANSIT_PARTS]
    return {"phase": PHASES[i], "nodes_planning": st.nodes_planning, "nodes_validating": st.nodes_validating,
            "edges_invalidated": st.edges_invalidated, "rrt_calls": st.rrt_calls, "searches": st.searches,
            "transit_checks": st.checks, "smoothing_checks": smoothing_checks,
            "path_length": round(float(np.linalg.norm(np.diff(seg, axis=0), axis=1).sum()), 4),
            "straight_distance": round(float(np.linalg.norm(seg[-1] - seg[0])), 4) if len(seg) else 0.0,
            "transit_length": round(float(sum(np.linalg.norm(np.diff(x, axis=0), axis=1).sum() for x in transits)), 4),
            "transit_straight": round(float(sum(np.linalg.norm(x[-1] - x[0]) for x in transits)), 4),
            "duration": round(float(len(sel) * dt), 4)}


def run(ctx: StepContext) -> StepOutput:
    i = ctx.inputs
    motion, seconds = plan_motion(ctx.scene, i["pick_grasps"], i["place_grasps"], i["double_grasps"], i["roadmap"], ctx.params,
                                  ctx.rng, ctx.progress)
    return StepOutput(motion, tuple(seconds))


NAME = "motion"
STEP = Step(NAME, "the whole task's motion: Grasp, Carry, Place, Rest on the Super Graph (V-B)",
            ("pick_grasps", "place_grasps", "double_grasps", "roadmap"), MotionParams, Motion, run)
