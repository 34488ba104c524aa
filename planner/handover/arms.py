"""The first step: which arm picks the object and which places it.

Each arm (with the torso) is tried on each placement (reach.py). When several picking/placing
pairs are possible (both arms reach a placement), the pair with the lower estimated exchange cost
is chosen: the palms' travel of the paper's exchange cost (exchange_grid.py) with the witness
configurations as grasp and place, at the exchange point minimising it (the geometric median of the
four palm positions the exchange connects). When one arm reaches both placements no handover is
needed: that arm both picks and places (a direct transfer: the later steps keep the grasps it can
hold at both placements, and the motion carries the object with it), unless the task asks for a
handover (`handover = true`). Arms can be forced with the step's parameters (the same arm twice: a
direct transfer); every failure message says how.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.collision.checker import build_collision_model
from planner.core.bounds import bounded, described
from planner.core.errors import RegraspError
from planner.core.results import array
from planner.core.steps import Step, StepContext, StepOutput
from planner.handover.exchange import palm_waypoints
from planner.handover.exchange_grid import exchange_costs
from planner.handover.reach import ReachResult, placement_reach
from planner.model.task import Scene

FORCE_HINT = "force the arms with --set arms.picking_arm=ARM --set arms.placing_arm=ARM"


@dataclass(frozen=True)
class ArmsParams:
    seeds: int = bounded(32, 1, 1000, "IK starts", "IK starts per arm and placement, to find which arm reaches it")
    tolerance: float = bounded(0.02, 0.001, 0.2, "m", "how close the fingertip centre must come to the object's centre of mass")
    picking_arm: str = described("", "force the picking arm (with placing_arm); empty: chosen from reachability and exchange cost")
    placing_arm: str = described("", "force the placing arm (with picking_arm); empty: chosen from reachability and exchange cost")


@dataclass(frozen=True)
class ArmAssignment:
    """The picking and placing arms, with a witness configuration of each reaching its placement."""

    picking_arm: str
    placing_arm: str
    distances: dict  # placement -> arm -> best distance (m)
    handover: bool  # false: one arm picks and places (it reaches both placements and the task did not ask for a handover)
    choice: str  # why these arms, in words
    costs: dict  # "picking>placing" -> estimated exchange cost (m), for every possible pair
    failure: str  # empty when the pipeline can go on
    q_pick: np.ndarray = array("float64", ("nq",))
    q_place: np.ndarray = array("float64", ("nq",))

    def stats(self) -> dict:
        return {"picking_arm": self.picking_arm, "placing_arm": self.placing_arm, "handover": self.handover,
                "choice": self.choice, **({"failure": self.failure} if self.failure else {})}


@dataclass(frozen=True)
class Decision:
    """The outcome of assigning arms from reachability: the pair (or the one arm), why, and what failed."""

    picking_arm: str
    placing_arm: str
    handover: bool
    choice: str
    costs: dict
    failure: str


def geometric_median(points: np.ndarray, iterations: int = 200) -> np.ndarray:
    """The point minimising the sum of distances to `points` (Weiszfeld's iteration from the centroid)."""
    e = points.mean(axis=0)
    for _ in range(iterations):
        d = np.maximum(np.linalg.norm(points - e, axis=1), 1e-9)
        e = (points / d[:, None]).sum(axis=0) / (1.0 / d).sum()
    return e


def exchange_cost_estimate(scene: Scene, picking: str, placing: str, q_pick: np.ndarray, q_place: np.ndarray) -> float:
    """The paper's exchange cost (m of palm travel) for a pair of arms, witness configurations as grasp and place."""
    w = palm_waypoints(scene, picking, placing, q_pick, q_place)
    e = geometric_median(np.array([w.pick_grasp, w.pick_final, w.place_initial, w.place_place]))
    return float(exchange_costs(e[None], w)[0])


def _reached(reaches: dict[str, dict[str, ReachResult]], name: str) -> list[str]:
    return [a for a, r in reaches[name].items() if r.reachable]


def forced_decision(scene: Scene, forced: tuple[str, str]) -> Decision:
    """The arms the step's parameters force (the same arm twice: a direct transfer), or a RegraspError when one is not an
    arm of the robot."""
    names = scene.robot.spec.arm_names
    if not all(a in names for a in forced):
        raise RegraspError(f"arms: picking_arm and placing_arm must be arms of the robot ({', '.join(names)}; the same one "
                           f"twice for a direct transfer); got '{forced[0]}' and '{forced[1]}'")
    direct = forced[0] == forced[1]
    return Decision(*forced, not direct, "forced by the step's parameters" + (" (one arm: a direct transfer)" if direct else ""),
                    {}, "")


def decide(scene: Scene, reaches: dict[str, dict[str, ReachResult]], forced: tuple[str, str] = ("", "")) -> Decision:
    """Choose the arms from each arm's reach of each placement (see the module docstring); `forced` overrides."""
    if any(forced):
        return forced_decision(scene, forced)
    initial, final = _reached(reaches, "initial"), _reached(reaches, "final")
    pairs = [(a, b) for a in initial for b in final if a != b]
    costs = {f"{a}>{b}": round(exchange_cost_estimate(scene, a, b, reaches["initial"][a].q, reaches["final"][b].q), 4)
             for a, b in pairs}
    both = [a for a in initial if a in final]
    if both and not scene.handover:
        arm = both[0]
        why = (f"no handover is needed: the {arm} arm reaches both placements and carries the object itself "
               "(set handover = true in the task to plan a regrasp anyway" + ("" if pairs else ", which needs "
               "the other arm to reach a placement") + f", or {FORCE_HINT})")
        return Decision(arm, arm, False, why, costs, "")
    if not pairs:
        reached = "; ".join(f"the {name} placement is reached by {', '.join(_reached(reaches, name)) or 'no arm'}"
                            for name in ("initial", "final"))
        failure = (f"no pair of arms can hand the object over: {reached} (each arm with the torso, fingertip centre within "
                   f"tolerance of the object's centre of mass, collision-free); move the placements, or {FORCE_HINT}")
        return Decision("", "", True, failure, costs, failure)
    a, b = min(pairs, key=lambda pair: (costs[f"{pair[0]}>{pair[1]}"], pair))
    if len(pairs) == 1:
        choice = f"the only possible pair: the {a} arm reaches the initial placement, the {b} arm the final one"
    else:
        others = ", ".join(f"{k.replace('>', ' picks, ')} places: {v:.2f} m" for k, v in costs.items() if k != f"{a}>{b}")
        choice = (f"several arms reach a placement: {a} picks and {b} places, the lower estimated exchange cost "
                  f"({costs[f'{a}>{b}']:.2f} m of palm travel; {others})")
    if scene.handover and both:
        choice += "; the task asks for a handover although one arm reaches both placements"
    return Decision(a, b, True, choice, costs, "")


def assign_arms(ctx: StepContext) -> StepOutput:
    scene, p = ctx.scene, ctx.params
    if p.picking_arm or p.placing_arm:
        forced_decision(scene, (p.picking_arm, p.placing_arm))  # bad names are refused before the reach search
    checker = build_collision_model(scene.robot, scene.environment).checker()
    reaches = placement_reach(scene, checker, p.seeds, p.tolerance, ctx.progress)
    d = decide(scene, reaches, (p.picking_arm, p.placing_arm))
    ctx.progress(1.0, d.failure or f"{d.picking_arm} picks, {d.placing_arm} places")
    distances = {name: {a: r.distance for a, r in per_arm.items()} for name, per_arm in reaches.items()}
    q_pick = reaches["initial"][d.picking_arm].q if d.picking_arm else scene.q_initial
    q_place = reaches["final"][d.placing_arm].q if d.placing_arm else scene.q_final
    return StepOutput(ArmAssignment(d.picking_arm, d.placing_arm, distances, d.handover, d.choice, d.costs, d.failure, q_pick, q_place))


STEP = Step("arms", "which arm picks and which places", (), ArmsParams, ArmAssignment, assign_arms)
