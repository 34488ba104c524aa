"""The motion of a table handover or a same-hand regrasp, composed of the same stages as a double grasp's
(double_grasp.py).

Grasp: the picking hand to the object, approach, closing. Set down: the lift, the carry to above the intermediate
placement, setting it down there, letting go, the retreat (a same-hand regrasp: the hand then opening fully, clear
of the object, as it must be for its next pre-grasp). Regrasp: the placing hand to the object at rest there (the
picking arm out of its way in the same transit), approach, closing. Carry: the lift, the carry to above the final
placement. Place: setting it down, letting go, the retreat. Rest: to the final configuration, the hands opening.
Every contact motion is made, and every transit end checked ready, before the five transits run at once.
"""
from __future__ import annotations

import numpy as np

from planner.collision.situation import Situation
from planner.motion.double_grasp import DoubleGraspPlanner
from planner.motion.fallbacks import raise_first
from planner.motion.phase import Phase
from planner.motion.piece import HandGrasp, Piece

GRASP, CARRY, PLACE, REST, SET_DOWN, REGRASP = Phase


def plan_table(planner: DoubleGraspPlanner, q_grasp: np.ndarray, q_set: np.ndarray, q_take: np.ndarray, q_place: np.ndarray,
               a: HandGrasp, b: HandGrasp, pose: np.ndarray) -> list[Piece]:
    """Every piece from q_initial to q_final through the intermediate placement `pose` (a: the picking hand, set
    down at q_set; b: the placing hand, taking the object at q_take and placing it at q_place; the same arm in
    another grasp for a same-hand regrasp)."""
    scene, arms, hand = planner.scene, planner.arms, planner.hand
    oi, of = scene.object_initial, scene.object_final
    idx = scene.robot.hand_idx

    # exact grasps, so the object's pose is continuous: the picking hand holds it at its listed grasp and sets it down
    # exactly at the placement as it holds it; the placing hand takes it exactly at its listed grasp (its fingers
    # closing on the object as the list has them), and places it as it took it; each hand open until it approaches,
    # then keeping its fingers as they let go until the end
    same = a.arm == b.arm
    q_grasp = arms.refine(q_grasp, a.arm, oi @ a.palm_in_object, None, GRASP, "grasp")
    g_a = np.linalg.inv(oi) @ arms.palm(q_grasp, a.arm)
    q_set = hand.set(q_set, a.arm, a.fingers) if same else hand.set(hand.set(q_set, a.arm, a.fingers), b.arm, hand.open[idx[b.arm]])
    q_set = arms.refine(q_set, a.arm, pose @ g_a, None, SET_DOWN, "set-down")
    grasps, first_grasp = planner.pick_up(GRASP, q_grasp, a, oi)
    q_lifted, lifted = planner.lift(SET_DOWN, q_grasp, a, g_a, oi)
    down_here, first_here = planner.set_downs(SET_DOWN, q_set, a.arm, g_a, pose)
    let_a, released_a = planner.release(SET_DOWN, q_set, a, pose)
    if same:  # the hand opens fully where it retreated to: its next pre-grasp is open
        released_a += planner.contact.fingers(SET_DOWN, "opening", released_a[-1].path[-1], a.arm, hand.open[idx[a.arm]],
                                              Situation(None, pose))
    held_fingers = hand.open[idx[a.arm]] if same else let_a  # the picking hand's fingers from there on

    q_take = arms.refine(hand.set(q_take, a.arm, held_fingers), b.arm, pose @ b.palm_in_object, None, REGRASP, "regrasp")
    g_b = np.linalg.inv(pose) @ arms.palm(q_take, b.arm)
    q_place = hand.set(arms.refine(hand.set(q_place, a.arm, held_fingers), b.arm, of @ g_b, None, PLACE, "place"), b.arm, b.fingers)
    takes, first_take = planner.pick_up(REGRASP, q_take, b, pose)
    q_lifted_b, lifted_b = planner.lift(CARRY, q_take, b, g_b, pose)
    downs, first_down = planner.set_downs(PLACE, q_place, b.arm, g_b, of)
    let_b, released_b = planner.release(PLACE, q_place, b, of)
    q_end, opening = planner.rest({a.arm: let_a, b.arm: let_b}, of)  # one arm: its fingers as it let go the second time

    held_a, held_b = Situation(a.arm, g_a), Situation(b.arm, g_b)
    q_after = released_a[-1].path[-1]
    carry, to_table, rest, to_grasp, to_take = planner.transits([
        (CARRY, lambda s: s.reach(q_lifted_b, downs, first_down, held_b)),
        (SET_DOWN, lambda s: s.reach(q_lifted, down_here, first_here, held_a)),
        (REST, lambda s: [s.transit(released_b[-1].path[-1], q_end, Situation(None, of))]),
        (GRASP, lambda s: s.reach(scene.q_initial, grasps, first_grasp, Situation(None, oi))),
        (REGRASP, lambda s: s.reach(q_after, takes, first_take, Situation(None, pose)))],
        [3, lifted, 1, released_a, 4, lifted_b, 0, released_b, 2, opening])
    raise_first([to_grasp, to_table, to_take, carry, rest])
    return to_grasp + lifted + to_table + released_a + to_take + lifted_b + carry + released_b + rest + opening
