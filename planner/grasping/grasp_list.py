"""Single-grasp lists (paper IV-A): grasp frames -> grasps -> stability filter -> quality -> a ranked, deduplicated list.

One list per hand. Frames run in a process pool (both cores), in chunks whose results are
gathered in frame order, so the list depends only on the inputs and the seed (which rotates the
orientation grid and shifts the position grid within a cell). Quality is a weighted sum of the
stability (epsilon over the list's best epsilon), the centre-of-mass score, the force-ellipsoid
score and the curvature score, all in [0, 1]. Lists are cached in the user cache, keyed by the
hand spec and URDF, the mesh, the parameters, the seed and the code version.
"""
from __future__ import annotations

import collections
import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from planner.collision.hand_placement import ObstacleTest, environment_filter
from planner.collision.pairs import CollisionParams
from planner.core.bounds import bounded
from planner.core.errors import RegraspError
from planner.core.forked import available_cpus, forked_map
from planner.core.results import array, load_result, read_only, save_result, writing
from planner.core.steps import Progress, Step, StepContext, StepOutput, no_progress, step_seed
from planner.core.user_cache import building, cache_key, cache_path, computing, read_cached
from planner.grasping.finger_workspace import FingerWorkspace, WorkspaceParams, hand_workspaces
from planner.grasping.frames import box_grid, hopf_rotations
from planner.grasping.object_model import ObjectModel, mesh_bytes, object_model
from planner.grasping.search import OUTCOMES, FrameGrasp, GraspSearch, SearchParams
from planner.model.hand_model import load_hand_model
from planner.model.robot_spec import HandSpec, RobotSpec

if TYPE_CHECKING:
    from planner.model.environment import Environment
    from planner.model.robot import Robot

CODE_VERSION = "grasps-3"  # 2: no seconds in the list; 3: frames rejected before the search have their own outcomes
CHUNKS_PER_WORKER = 6


@dataclass(frozen=True)
class GraspParams:
    """Everything a grasp list depends on besides the hand, the mesh and the seed."""

    positions: int = bounded(80, 1, 1000, "positions", "grasp-frame positions on a grid in the object's bounding box")
    orientations: int = bounded(160, 1, 1000, "orientations", "grasp-frame orientations per position (an incremental SO(3) sequence)")
    mu: float = bounded(0.5, 0.01, 2.0, "(friction coefficient)", "friction coefficient of the fingertip contacts")
    cone_edges: int = bounded(8, 3, 64, "edges", "edges of the linearised friction cone")
    point_step: float = bounded(0.5, 0.2, 5.0, "fingertip radii", "spacing of the object's surface points")
    ik_tolerance: float = bounded(2e-4, 1e-5, 0.01, "m", "a fingertip centre's distance to its target, at most")
    ik_iterations: int = bounded(4, 1, 100, "iterations", "damped least-squares steps from the nearest workspace sample")
    contact_clearance: float = bounded(1e-3, 0.0, 0.01, "m", "the touching fingertip is shrunk by this for the collision test")
    press_angle: float = bounded(1.4, 0.0, 3.1416, "rad", "angle between the closing motion and the inward normal, at most")
    max_candidates: int = bounded(48, 1, 1000, "candidates", "contact candidates tried per finger and frame")
    ik_batch: int = bounded(16, 1, 1024, "candidates", "contact candidates solved per IK batch")
    limit_margin: float = bounded(0.1, 0.0, 0.45, "(fraction)", "finger joint ranges reduced by this fraction at both ends")
    samples_per_joint: int = bounded(14, 2, 30, "samples", "finger workspace samples per joint (this to the power of a finger's joints)")
    voxel: float = bounded(0.004, 0.001, 0.05, "m", "finger workspace grid step")
    max_spheres: int = bounded(40, 1, 1000, "spheres", "spheres approximating a finger's workspace, at most")
    min_radius: float = bounded(0.006, 0.001, 0.1, "m", "a finger's workspace spheres stop when the next would be smaller")
    w_stability: float = bounded(1.0, 0.0, 100.0, "(weight)", "quality weight of the stability score (epsilon over the list's best)")
    w_com: float = bounded(0.25, 0.0, 100.0, "(weight)", "quality weight of the centre-of-mass score (contacts near the centre of mass)")
    w_ellipsoid: float = bounded(
        0.25, 0.0, 100.0, "(weight)", "quality weight of the force-ellipsoid score (normals along each finger's strongest direction)")
    w_curvature: float = bounded(
        0.25, 0.0, 100.0, "(weight)", "quality weight of the curvature score (contacts on surfaces the fingertip fits)")
    dedup_distance: float = bounded(0.01, 0.0, 0.1, "m", "grasps whose contacts (same fingers) are all this close count as one")
    min_clear: int = bounded(
        30, 0, 10000, "grasps", "grasps clear of the obstacles at the placement, at least (else searched again, densified)")
    densify: int = bounded(3, 1, 20, "(factor)", "orientations multiplied by this when fewer than min_clear grasps are clear")

    def workspace(self) -> WorkspaceParams:
        return WorkspaceParams(self.limit_margin, self.samples_per_joint, self.voxel, self.max_spheres, self.min_radius)

    def search(self) -> SearchParams:
        return SearchParams(self.mu, self.cone_edges, self.ik_tolerance, self.ik_iterations, self.contact_clearance, self.max_candidates,
                            self.ik_batch, self.press_angle)


@dataclass(frozen=True)
class GraspList:
    """A ranked list of single grasps of one hand (best first); poses and contacts in the object frame."""

    hand: str  # the arm whose hand this is
    fingers: list  # finger names, the order of the finger axis and of finger_q
    tip_radius: list  # per finger, m
    mu: float
    cone_edges: int
    torque_scale: float  # m: the length torques are divided by (object radius about its centre of mass)
    object_com: list
    frames_tried: int
    outcomes: dict  # outcome name -> number of frames
    kept: int
    hand_pose: np.ndarray = array("float64", ("n", 4, 4))
    finger_q: np.ndarray = array("float64", ("n", None))
    contact_point: np.ndarray = array("float64", ("n", "f", 3))
    contact_normal: np.ndarray = array("float64", ("n", "f", 3))
    contact_mask: np.ndarray = array("bool", ("n", "f"))
    epsilon: np.ndarray = array("float64", ("n",))
    com_distance: np.ndarray = array("float64", ("n",))
    com_score: np.ndarray = array("float64", ("n",))
    ellipsoid: np.ndarray = array("float64", ("n",))
    curvature: np.ndarray = array("float64", ("n",))
    quality: np.ndarray = array("float64", ("n",))

    SCORES = ("epsilon", "com_distance", "com_score", "ellipsoid", "curvature", "quality")

    def __len__(self) -> int:
        return len(self.quality)

    @property
    def contacts_found(self) -> int:
        """Frames whose grasp reached three contacts (force-closed or not)."""
        return self.outcomes.get("not_closed", 0) + self.outcomes.get("closed", 0)

    @property
    def failure(self) -> str:
        """Empty when the list holds a grasp; else the grasp step's failure, with the count at every stage."""
        if self.kept:
            return ""
        return (f"no force-closed grasp of the {self.hand} hand on the object (frames tried: {self.frames_tried}; "
                f"contacts found: {self.contacts_found}; force-closed: {self.outcomes.get('closed', 0)}); "
                "is the object the size the hand holds (see `regrasp check`)?")

    def stats(self) -> dict:
        return {"hand": self.hand, "frames": self.frames_tried, "contacts_found": self.contacts_found,
                "force_closed": self.outcomes.get("closed", 0), "kept": self.kept,
                "best_quality": round(float(self.quality[0]), 4) if len(self) else None,
                **({"failure": self.failure} if self.failure else {})}

    def contacts(self, rank: int) -> list[dict]:
        """The contacts of the grasp at a rank: finger name, point and outward normal (object frame)."""
        return [{"finger": f, "point": self.contact_point[rank, i].tolist(), "normal": self.contact_normal[rank, i].tolist()}
                for i, f in enumerate(self.fingers) if self.contact_mask[rank, i]]

    def to_json(self, seconds: float) -> dict:
        """The list as outside tools read it, with the `seconds` this run took to get it (names fixed by the issue: keep them)."""
        grasps = []
        for r in range(len(self)):
            g = {"hand_pose": self.hand_pose[r].tolist(), "finger_q": self.finger_q[r].tolist(), "contacts": self.contacts(r)}
            g.update({s: float(getattr(self, s)[r]) for s in self.SCORES})
            grasps.append(g)
        return {"hand": self.hand, "fingers": list(self.fingers), "mu": self.mu, "cone_edges": self.cone_edges,
                "torque_scale": self.torque_scale, "object_com": list(self.object_com), "seconds": seconds,
                "frames_tried": self.frames_tried, "outcomes": dict(self.outcomes), "grasps": grasps}


def hand_spec_of(spec: RobotSpec, hand: str) -> HandSpec:
    """The hand of the arm named `hand`, or an error listing the arms."""
    if hand not in spec.arm_names:
        raise RegraspError(f"robot '{spec.name}' has no hand '{hand}' (hands, by arm: {', '.join(spec.arm_names)})")
    return spec.arm(hand).hand


def grasp_centre(workspaces: tuple[FingerWorkspace, ...]) -> np.ndarray:
    """The point (hand frame) the grasp frame is centred on: the mean of each finger's largest workspace sphere."""
    if any(len(w.radii) == 0 for w in workspaces):
        raise RegraspError("a finger's workspace holds no sphere: lower min_radius or voxel")
    return np.mean([w.centres[0] for w in workspaces], axis=0)


def grasp_frames(mesh: trimesh.Trimesh, centre: np.ndarray, p: GraspParams, seed: int) -> np.ndarray:
    """(N, 4, 4) hand poses: the grasp centre at each grid position, in each orientation (position-major)."""
    rng = np.random.default_rng(seed)
    turn = Rotation.random(random_state=rng).as_matrix()
    positions = box_grid(mesh.bounds[0], mesh.bounds[1], p.positions, rng.uniform(-0.5, 0.5, 3))
    rotations = turn @ hopf_rotations(p.orientations)
    H = np.tile(np.eye(4), (len(positions), len(rotations), 1, 1))
    H[:, :, :3, :3] = rotations[None]
    H[:, :, :3, 3] = positions[:, None, :] - rotations[None] @ centre
    return H.reshape(-1, 4, 4)


def search_object(mesh: trimesh.Trimesh, tip_radius: Sequence[float], p: GraspParams) -> ObjectModel:
    """The object model a hand with these fingertip radii searches: points spaced by the smallest radius."""
    return object_model(mesh, p.point_step * min(tip_radius))


def _run_frames(search: GraspSearch, frames: np.ndarray, workers: int, progress: Progress) -> list[FrameGrasp]:
    """Every frame's grasp, in frame order, in chunks over `workers` forked processes sharing the (read-only) search."""
    chunks = np.array_split(frames, max(1, workers * CHUNKS_PER_WORKER))
    out: list[FrameGrasp] = []

    def arrived(part: list[FrameGrasp]) -> None:
        out.extend(part)
        progress(len(out) / len(frames), f"{len(out)} of {len(frames)} frames")

    forked_map(search.grasps, chunks, workers, arrived)
    return out


def _deduplicated(order: np.ndarray, points: np.ndarray, mask: np.ndarray, distance: float) -> np.ndarray:
    """The grasps of `order` (best first) that have no better grasp with the same fingers and every contact within `distance`."""
    kept: list[int] = []
    for i in order:
        if kept:
            same = np.all(mask[kept] == mask[i], axis=1)
            near = np.all(np.where(mask[i], np.linalg.norm(points[kept] - points[i], axis=2) <= distance, True), axis=1)
            if np.any(same & near):
                continue
        kept.append(int(i))
    return np.asarray(kept, int)


def compute_grasp_list(spec: HandSpec, arm: str, mesh: trimesh.Trimesh, p: GraspParams, seed: int,
                       progress: Progress = no_progress, workers: int | None = None) -> GraspList:
    """Compute one hand's ranked grasp list on a mesh (no cache)."""
    workers = min(2, available_cpus()) if workers is None else workers
    hand = load_hand_model(spec)
    progress(0.0, "object point set and finger workspaces")
    obj = search_object(mesh, [f.tip_radius for f in hand.fingers], p)
    workspaces = hand_workspaces(hand, p.workspace())
    search = GraspSearch(hand, workspaces, obj, mesh, p.search(), p.limit_margin)
    frames = grasp_frames(mesh, grasp_centre(workspaces), p, seed)
    found = _run_frames(search, frames, workers, progress)
    closed = [g for g in found if g.outcome == "closed"]
    f = len(hand.fingers)
    contact = np.array([g.contact_index for g in closed], int).reshape(-1, f)
    mask = contact >= 0
    points = np.where(mask[..., None], obj.points[np.maximum(contact, 0)], 0.0)
    normals = np.where(mask[..., None], obj.normals[np.maximum(contact, 0)], 0.0)
    scores = {s: np.array([getattr(g, s) for g in closed], float)
              for s in ("epsilon", "com_distance", "com_score", "ellipsoid", "curvature")}
    best_eps = scores["epsilon"].max() if closed else 1.0
    quality = (p.w_stability * scores["epsilon"] / best_eps + p.w_com * scores["com_score"]
               + p.w_ellipsoid * scores["ellipsoid"] + p.w_curvature * scores["curvature"])
    keep = _deduplicated(np.argsort(-quality, kind="stable"), points, mask, p.dedup_distance)
    outcomes = collections.Counter(g.outcome for g in found)
    poses = np.array([g.hand_pose for g in closed], float).reshape(-1, 4, 4)
    finger_q = np.array([g.finger_q for g in closed], float).reshape(-1, hand.dof)
    progress(1.0, f"{len(keep)} grasps kept")
    return GraspList(
        hand=arm, fingers=list(hand.finger_names), tip_radius=[fi.tip_radius for fi in hand.fingers], mu=p.mu,
        cone_edges=p.cone_edges, torque_scale=obj.radius, object_com=obj.com.tolist(),
        frames_tried=len(frames), outcomes={o: outcomes.get(o, 0) for o in OUTCOMES},
        kept=len(keep), hand_pose=poses[keep], finger_q=finger_q[keep], contact_point=points[keep],
        contact_normal=normals[keep], contact_mask=mask[keep], quality=quality[keep],
        **{s: v[keep] for s, v in scores.items()})


def grasp_list(spec: RobotSpec, arm: str, mesh: trimesh.Trimesh, p: GraspParams, seed: int, progress: Progress = no_progress,
               use_cache: bool = True, workers: int | None = None) -> tuple[GraspList, bool]:
    """One hand's grasp list from the user cache, else computed (and cached); also whether it came from the cache."""
    hand = hand_spec_of(spec, arm)
    searched = dataclasses.replace(p, min_clear=GraspParams.min_clear, densify=GraspParams.densify)  # not the list's
    key = cache_key(CODE_VERSION, repr(hand), hand.urdf.read_bytes(), mesh_bytes(mesh), repr(searched), str(seed), arm)
    folder = cache_path("grasps", key)
    with computing(folder):
        if use_cache:
            cached = read_cached([folder / "grasps.json", folder / "grasps.npz"], lambda: load_result(GraspList, folder, "grasps"),
                                 f"grasp list of the {arm} hand")
            if cached is not None:
                return cached, True
        with building(f"the grasp list of the {arm} hand ({p.positions * p.orientations} frames, entry {key})"):
            result = compute_grasp_list(hand, arm, mesh, p, seed, progress, workers)
            with writing(folder):
                folder.mkdir(parents=True, exist_ok=True)
            save_result(result, folder, "grasps")
    return read_only(result), False


SEED_NAME = "grasps"  # both grasp steps derive their seed from this name: a hand's list depends on the hand, not its role


def seed_of(rng: np.random.Generator) -> int:
    """A grasp list's seed, drawn from the step's generator (so the session seed decides it)."""
    return int(rng.integers(2**31))


def session_grasp_seed(session_seed: int) -> int:
    """The seed a session with this seed computes its grasp lists with: `regrasp grasps --seed S` shares `plan --seed S`'s."""
    return seed_of(np.random.default_rng(step_seed(session_seed, SEED_NAME)))


def clear_count(robot: Robot, grasps: GraspList, object_pose: np.ndarray, environment: Environment) -> int:
    """How many grasps of a list keep the hand clear of the obstacles (by the collision model's padding) with the
    object at a pose: those the grasp configurations step goes on with."""
    obstacles = ObstacleTest.of_environment(environment, CollisionParams().env_padding)
    return int(environment_filter(robot, grasps, object_pose, obstacles).sum())


def _step_run(role: str) -> Any:
    def run(ctx: StepContext) -> StepOutput:
        scene, p, seed = ctx.scene, ctx.params, seed_of(ctx.rng)
        arm = getattr(ctx.inputs["arms"], f"{role}_arm")
        grasps, cached = grasp_list(scene.robot.spec, arm, scene.object_mesh, p, seed, ctx.progress)
        pose = scene.object_initial if role == "picking" else scene.object_final
        clear = clear_count(scene.robot, grasps, pose, scene.environment)
        if clear < p.min_clear and p.densify > 1:
            ctx.progress(0.0, f"{clear} of {len(grasps)} grasps clear the obstacles at the placement (fewer than {p.min_clear}): "
                              f"searching {p.densify} times the orientations")
            grasps, denser_cached = grasp_list(scene.robot.spec, arm, scene.object_mesh,
                                               dataclasses.replace(p, orientations=p.orientations * p.densify), seed, ctx.progress)
            cached = cached and denser_cached
        return StepOutput(grasps, cached=cached)

    run.__doc__ = f"The {role} hand's grasp list (paper IV-A)."
    return run


PICK_STEP = Step("pick_grasps", "grasp list of the picking hand", ("arms",), GraspParams, GraspList, _step_run("picking"), SEED_NAME)
PLACE_STEP = Step("place_grasps", "grasp list of the placing hand", ("arms",), GraspParams, GraspList, _step_run("placing"), SEED_NAME)
