"""Double grasps (paper IV-B) and their exchange configurations (V-C).

Every pair (pick grasp, place grasp) whose grasps have robot configurations is tested: pairs whose
hands collide with each other on the object are rejected. A pair scores the minimum of its two
grasp qualities plus the minimum of its two configuration scores, each normalised by its largest
value over the compatible pairs. Down the ranking, each pair gets an exchange configuration: the
object's orientation turns each grasp's approach direction towards its arm's shoulder (Wahba's
problem, scipy), its position is the best exchange node, then Gaussian samples around it; the torso
is sampled near the task's start (near the rest with grasp_configs.free_around = "rest") and both
arms are solved by IK; the object is tested against the environment and the robot against itself,
the environment and the object. The first `count` pairs that get one are returned, best first.
A direct transfer (one arm picks and places) pairs each grasp with itself: the grasps with a
configuration at both placements, ranked the same way; the object never changes hands, so a row's
exchange configuration is its place configuration and its exchange pose the final placement.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from planner.collision.hand_placement import hands_collide, posed_shapes
from planner.collision.object_obstacle import ObjectCollision
from planner.core.bounds import bounded
from planner.core.results import array
from planner.core.stages import StageLog
from planner.core.steps import Step, StepContext, StepOutput
from planner.grasping.grasp_list import GraspList
from planner.handover.grasp_configs import ConfigSampler
from planner.handover.reach import approach_direction
from planner.model.hand_model import load_hand_model


@dataclass(frozen=True)
class DoubleGraspParams:
    count: int = bounded(
        20, 1, 1000, "double grasps", "double grasps wanted with an exchange configuration (the motion falls back down this list)")
    max_pairs: int = bounded(40, 1, 10000, "pairs", "grasp pairs tried, best first, before giving up")
    attempts: int = bounded(16, 1, 1000, "configurations", "exchange configurations sampled per pair")
    position_sigma: float = bounded(0.03, 0.0, 0.5, "m", "spread of the object's position around the best exchange node")
    rotation_sigma: float = bounded(0.15, 0.0, 3.1416, "rad", "spread of the object's orientation around the one the grasp directions give")
    torso_sigma: float = bounded(0.1, 0.0, 3.1416, "rad", "spread of the torso joints sampled around rest")
    hand_margin: float = bounded(0.0, 0.0, 0.5, "m", "the two hands on the object must be this far apart")


@dataclass(frozen=True)
class DoubleGrasps:
    """Ranked double grasps with the robot's grasp, exchange and place configurations and the object's exchange pose."""

    picking_arm: str
    placing_arm: str
    pairs: int  # pairs of grasps with configurations
    compatible: int  # pairs whose hands do not collide on the object
    tried: int  # compatible pairs tried for an exchange configuration
    stages: list
    failure: str
    pick_rank: np.ndarray = array("int64", ("n",))  # rank in the pick grasp list
    place_rank: np.ndarray = array("int64", ("n",))
    q_grasp: np.ndarray = array("float64", ("n", "nq"))
    q_exch: np.ndarray = array("float64", ("n", "nq"))
    q_place: np.ndarray = array("float64", ("n", "nq"))
    object_exchange: np.ndarray = array("float64", ("n", 4, 4))
    quality: np.ndarray = array("float64", ("n",))  # normalised minimum grasp quality
    config: np.ndarray = array("float64", ("n",))  # normalised minimum configuration score
    score: np.ndarray = array("float64", ("n",))

    def __len__(self) -> int:
        return len(self.score)

    def stats(self) -> dict:
        return {"pairs": self.pairs, "compatible": self.compatible, "tried": self.tried, "double_grasps": len(self),
                **({"failure": self.failure} if self.failure else {})}


def compatible_pairs(robot, pick: GraspList, place: GraspList, pick_ranks: np.ndarray, place_ranks: np.ndarray,
                     margin: float) -> np.ndarray:
    """(n, 2) indices into pick_ranks / place_ranks of the pairs whose hands stay apart on the object."""
    hands = {g.hand: load_hand_model(robot.spec.arm(g.hand).hand) for g in (pick, place)}
    a = [posed_shapes(hands[pick.hand], pick.finger_q[r], pick.hand_pose[r]) for r in pick_ranks]
    b = [posed_shapes(hands[place.hand], place.finger_q[r], place.hand_pose[r]) for r in place_ranks]
    return np.array([(i, j) for i in range(len(a)) for j in range(len(b)) if not hands_collide(a[i], b[j], margin)],
                    np.int64).reshape(-1, 2)


def same_grasps(pick: GraspList, place: GraspList, pick_ranks: np.ndarray, place_ranks: np.ndarray) -> np.ndarray:
    """(n, 2) indices into pick_ranks / place_ranks of the same grasp (hand pose and fingers) in both lists: for a direct
    transfer, the grasps the arm holds at both placements."""
    return np.array([(i, j) for i, r in enumerate(pick_ranks) for j, s in enumerate(place_ranks)
                     if np.array_equal(pick.hand_pose[r], place.hand_pose[s]) and np.array_equal(pick.finger_q[r], place.finger_q[s])],
                    np.int64).reshape(-1, 2)


def normalised(x: np.ndarray) -> np.ndarray:
    top = np.max(x) if len(x) else 0.0
    return x / top if top > 0 else np.ones_like(x)


def exchange_orientation(approach: list[np.ndarray], towards: list[np.ndarray]) -> np.ndarray:
    """The object rotation turning each grasp's approach direction (object frame) towards its direction (world)."""
    rotation, _ = Rotation.align_vectors(np.array(towards), np.array(approach))
    return rotation.as_matrix()


def exchange_configuration(sampler: ConfigSampler, collision: ObjectCollision, hands: tuple, R: np.ndarray, node: np.ndarray,
                           starts: tuple[np.ndarray, np.ndarray, np.ndarray], p: DoubleGraspParams,
                           rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray] | None:
    """(q_exch, object pose) with both hands at their grasps on the object near `node`, collision-free; None if not found.

    hands: ((picking arm, hand pose on the object, finger q), (placing arm, ...)). The first sample puts the object
    at the node in orientation R, later ones perturb both. The arms start alternately from the initial
    configuration and from their grasp / place configurations (starts); both arms and the sampled torso
    are solved together.
    """
    robot = sampler.robot
    com = collision.com
    (a, H1, f1), (b, H2, f2) = hands
    for attempt in range(p.attempts):
        T = np.eye(4)
        T[:3, :3] = R if attempt == 0 else Rotation.from_rotvec(rng.normal(0.0, p.rotation_sigma, 3)).as_matrix() @ R
        position = node if attempt == 0 else node + rng.normal(0.0, p.position_sigma, 3)
        T[:3, 3] = position - T[:3, :3] @ com
        if collision.object_hits_environment(T):
            continue
        q = sampler.body(rng, [])
        for n, arm in enumerate((a, b)):
            source = starts[0] if attempt % 2 == 0 else starts[1 + n]
            q[robot.arm_idx[arm]] = source[robot.arm_idx[arm]]
        q = sampler.reach({a: (T @ H1, f1), b: (T @ H2, f2)}, q)
        if q is not None and not collision.in_collision(q, T, (a, b)):
            return q, T
    return None


def run(ctx: StepContext) -> StepOutput:
    scene, p = ctx.scene, ctx.params
    robot = scene.robot
    pick, place = ctx.inputs["pick_grasps"], ctx.inputs["place_grasps"]
    configs, exchange = ctx.inputs["grasp_configs"], ctx.inputs["exchange"]
    a, b = configs.picking_arm, configs.placing_arm
    hp, hq = configs.hand("pick"), configs.hand("place")
    log = StageLog()
    log.done("pairs with configurations", len(hp.rank) * len(hq.rank), f"{len(hp.rank)} pick x {len(hq.rank)} place grasps")
    ctx.progress(0.0, "hands on the object")
    direct = a == b
    if direct:
        pairs = same_grasps(pick, place, hp.rank, hq.rank)
        log.done("grasps held at both placements", len(pairs), f"a direct transfer: the {a} arm picks and places")
    else:
        pairs = compatible_pairs(robot, pick, place, hp.rank, hq.rank, p.hand_margin)
        log.done("compatible pairs", len(pairs), "hands apart on the object")
    i, j = pairs[:, 0], pairs[:, 1]
    quality = normalised(np.minimum(pick.quality[hp.rank[i]], place.quality[hq.rank[j]]))
    config = normalised(np.minimum(hp.score[i], hq.score[j]))
    score = quality + config
    order = np.lexsort((np.arange(len(pairs)), -score))
    collision = ObjectCollision(scene)
    config_params = dataclasses.replace(ctx.input_params["grasp_configs"], torso_sigma=p.torso_sigma)
    scorer = config_params.scorer(robot, scene.q_initial)  # the torso around the task's start (grasp_configs.free_around)
    sampler = ConfigSampler(robot, collision, scorer, config_params)
    approach = {arm: approach_direction(robot, arm) for arm in (a, b)}
    shoulders = dict(zip(robot.spec.arm_names, np.asarray(exchange.shoulders)))
    found: list = []
    tried = 0
    if direct:  # each grasp is its own pair; its place configuration stands for the exchange (there is none)
        found = [(k, hq.q[j[k]], scene.object_final) for k in order[: p.count]]
    else:
        for k in order[: p.max_pairs]:
            if len(found) >= p.count or not len(exchange.best):
                break
            tried += 1
            ctx.progress(tried / p.max_pairs, f"exchange configuration of pair {tried} ({len(found)} found)")
            r1, r2 = hp.rank[i[k]], hq.rank[j[k]]
            H1, H2 = pick.hand_pose[r1], place.hand_pose[r2]
            node = exchange.position
            R = exchange_orientation([H1[:3, :3] @ approach[a], H2[:3, :3] @ approach[b]],
                                     [(node - shoulders[a]) / np.linalg.norm(node - shoulders[a]),
                                      (node - shoulders[b]) / np.linalg.norm(node - shoulders[b])])
            starts = (scene.q_initial, hp.q[i[k]], hq.q[j[k]])
            hands = ((a, H1, pick.finger_q[r1]), (b, H2, place.finger_q[r2]))
            result = exchange_configuration(sampler, collision, hands, R, node, starts, p, ctx.rng)
            if result is not None:
                found.append((k, *result))
        log.done("exchange configurations", len(found), f"of {tried} pairs tried, {p.attempts} samples each")
    failure = ""
    if direct and not len(pairs):
        failure = log.failure(f"no grasp of the {a} hand has a configuration at both placements, which a direct transfer needs "
                              "(set handover = true in the task to plan a regrasp with both hands)")
    elif not len(pairs):
        failure = log.failure("no compatible pair: every pick grasp collides with every place grasp on the object")
    elif not found:
        failure = log.failure("no exchange configuration: no pair tried could be held by both hands at the exchange position")
    ks = np.array([f[0] for f in found], np.int64)
    nq = robot.nq
    ctx.progress(1.0, f"{len(found)} double grasps")
    return StepOutput(DoubleGrasps(
        a, b, len(hp.rank) * len(hq.rank), len(pairs), tried, log.stages, failure,
        pick_rank=hp.rank[i[ks]], place_rank=hq.rank[j[ks]], q_grasp=hp.q[i[ks]].reshape(-1, nq),
        q_exch=np.array([f[1] for f in found]).reshape(-1, nq), q_place=hq.q[j[ks]].reshape(-1, nq),
        object_exchange=np.array([f[2] for f in found]).reshape(-1, 4, 4), quality=quality[ks], config=config[ks], score=score[ks]),
        tuple(log.seconds))


NAME = "double_grasps"
STEP = Step(NAME, "double grasps ranked, with exchange configurations (IV-B, V-C)",
            ("pick_grasps", "place_grasps", "grasp_configs", "exchange"), DoubleGraspParams, DoubleGrasps, run,
            recoverable=True)  # no double grasp: the motion may still hand the object over through the table
