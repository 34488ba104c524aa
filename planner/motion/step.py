"""The motion step (paper V-B): the whole task as one trajectory, the double grasps tried best first.

Each double grasp is planned by its stages (double_grasp.py); the first whose every piece is valid is
timed (timing.py) and sampled at a fixed rate. Measurements (seconds per phase and part) go to the
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
from planner.motion.piece import HandGrasp, Piece, PieceFailed
from planner.motion.result import PHASES, Motion, MotionParams
from planner.motion.timing import sample_polyline
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
    motion = _sampled(scene, pieces, p, tried, resolution, planner)
    seconds = [x for s in planner.stats for x in (s.seconds_planning, s.seconds_validating, s.seconds_reconnecting, s.seconds_shortcut,
                                                   s.seconds_contact)] + [time.perf_counter() - t]
    progress(1.0, f"{motion.duration:.1f} s of motion with double grasp {len(tried)}")
    return motion, seconds


def _empty(p: MotionParams, robot, tried: list, resolution: dict, failure: str) -> Motion:
    nq = robot.nq
    return Motion(p.planner, -1, tried, [], list(robot.spec.arm_names), resolution, [], failure, np.zeros(0), np.zeros((0, nq)),
                  np.zeros(0, np.int8), np.zeros((0, 4, 4)), np.zeros(0, np.int8), np.zeros(0, np.int8), np.zeros((0, 2, 3)),
                  np.zeros(5, np.int64), tuple(robot.joint_names()))


def _sampled(scene: Scene, pieces: list[Piece], p: MotionParams, tried: list, resolution: dict, planner: DoubleGraspPlanner) -> Motion:
    """Time every piece, sample it, and pose the object and wrists at every sample."""
    robot = scene.robot
    arms = list(robot.spec.arm_names)
    vmax = np.minimum(np.asarray(robot.model.velocityLimit, float), p.max_velocity)
    amax = np.full(robot.nq, p.max_acceleration)
    dt = 1.0 / p.rate
    qs, phase, holder, active, poses, ends = [scene.q_initial[None]], [0], [-1], [-1], [scene.object_initial[None]], []
    data = robot.model.createData()
    palms = {a: robot.frame_id(robot.palm_frame(a)) for a in arms}
    mounts = [robot.frame_id(robot.spec.arm(a).hand.mount_frame) for a in arms]
    wrists = []
    for piece in pieces:
        _, q = sample_polyline(piece.path, vmax, amax, dt)
        s = piece.situation
        for qi in q:
            pin.framesForwardKinematics(robot.model, data, qi)
            palm = data.oMf[palms[s.holder]].homogeneous if s.holder else None
            poses.append(s.object_pose(palm)[None])
            wrists.append([data.oMf[m].translation.copy() for m in mounts])
        qs.append(q)
        phase += [int(piece.phase)] * len(q)  # stored as the phase's integer
        holder += [arms.index(s.holder) if s.holder else -1] * len(q)
        active += [arms.index(piece.hand) if piece.hand else -1] * len(q)
        ends.append(sum(len(x) for x in qs) - 1)
    pin.framesForwardKinematics(robot.model, data, scene.q_initial)
    wrists.insert(0, [data.oMf[m].translation.copy() for m in mounts])
    q = np.concatenate(qs)
    phase_arr = np.array(phase, np.int8)
    grasped, exchanged, placed = (next((ends[i] for i, pc in enumerate(pieces) if (pc.phase, pc.part) == mark), None)
                                  for mark in ((0, "closing"), (1, "closing"), (2, "set-down")))
    key = [0, grasped, placed if exchanged is None else exchanged, placed, len(q) - 1]  # a direct transfer: no exchange
    t = np.arange(len(q)) * dt
    table = []
    for i, st in enumerate(planner.stats):
        sel = np.flatnonzero(phase_arr == i)
        seg = q[sel[0] - 1 if sel[0] else 0: sel[-1] + 1] if len(sel) else q[:0]
        table.append({"phase": PHASES[i], "nodes_planning": st.nodes_planning, "nodes_validating": st.nodes_validating,
                      "edges_invalidated": st.edges_invalidated, "rrt_calls": st.rrt_calls, "searches": st.searches,
                      "transit_checks": st.checks,
                      "path_length": round(float(np.linalg.norm(np.diff(seg, axis=0), axis=1).sum()), 4),
                      "duration": round(float(len(sel) * dt), 4)})
    stages = []
    for row in table:
        stages += [{"stage": f"{row['phase']}: transit planning", "count": row["nodes_planning"], "note": f"{row['searches']} searches"},
                   {"stage": f"{row['phase']}: transit validation", "count": row["edges_invalidated"], "note": "edges invalidated"},
                   {"stage": f"{row['phase']}: RRT reconnection", "count": row["nodes_validating"],
                    "note": f"nodes added by {row['rrt_calls']} RRTConnect calls"},
                   {"stage": f"{row['phase']}: shortcutting", "count": 0, "note": ""},
                   {"stage": f"{row['phase']}: approach, fingers, lift", "count": 0,
                    "note": f"path {row['path_length']:.2f} rad, {row['duration']:.2f} s"}]
    stages.append({"stage": "timing and sampling", "count": len(q), "note": f"samples at {p.rate:g} Hz"})
    return Motion(p.planner, len(tried) - 1, tried, table, arms, resolution, stages, "", t, q, phase_arr, np.concatenate(poses),
                  np.array(holder, np.int8), np.array(active, np.int8), np.array(wrists), np.array(key, np.int64),
                  tuple(robot.joint_names()))


def run(ctx: StepContext) -> StepOutput:
    i = ctx.inputs
    motion, seconds = plan_motion(ctx.scene, i["pick_grasps"], i["place_grasps"], i["double_grasps"], i["roadmap"], ctx.params,
                                  ctx.rng, ctx.progress)
    return StepOutput(motion, tuple(seconds))


NAME = "motion"
STEP = Step(NAME, "the whole task's motion: Grasp, Carry, Place, Rest on the Super Graph (V-B)",
            ("pick_grasps", "place_grasps", "double_grasps", "roadmap"), MotionParams, Motion, run)
