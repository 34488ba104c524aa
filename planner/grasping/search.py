"""The grasps at many grasp frames at once (paper IV-A.2): finger by finger, thumb first, all frames of a batch together.

Frames the hand cannot grasp from are dropped first (reject.py). Then, for each finger, every kept
frame's contact candidates (candidates.py: object points p with outward normal n whose fingertip
target p + r n lies in the finger's workspace spheres) are ranked: largest sphere first; within a
sphere (the paper leaves the order open) the thumb takes the point nearest the sphere's centre, the
other fingers the surface most opposed to the contacts already made (force closure needs opposition).
The candidates' IK is solved for all frames in one call, in rounds of `ik_batch` candidates per
frame (each frame's batch stops on its own, as if solved alone), seeded from the nearest workspace
sample; a solution counts when closing the finger pushes its tip into the surface (within
`press_angle` of the inward normal: a finger can only squeeze by closing). A frame takes its first
candidate, in rank order, whose finger is collision-free with the object (the fingertip sphere
shrunk by a clearance, since it touches) and with the fingers already placed: certain hits are
screened out for all candidates at once, and so are shapes certainly clear of the object
(planner/collision/object_screens.py); coal's exact test decides the rest. A finger
without contact stays open and must be collision-free too. Grasps of >= 3 contacts go to the
stability filter, where a separating hyperplane rules most out before the exact hull.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from planner.collision.hand_placement import ObjectTest
from planner.collision.object_screens import SPHERE_MARGIN, ObjectScreen, Posed, bounding, inside_of
from planner.collision.shapes import Geometry, sphere, transform3s
from planner.grasping.candidates import CandidateFinder, Candidates
from planner.grasping.finger_workspace import FingerWorkspace
from planner.grasping.object_model import ObjectModel
from planner.grasping.quality import com_score, contact_wrenches, curvature_score, ellipsoid_alignment, separated, wrench_closure
from planner.grasping.reject import MIN_CONTACTS, REJECTIONS, rejected
from planner.model.hand_model import FingerChain, HandModel

# Why a frame yields no grasp (or the grasp it yields), in the order the search meets them.
OUTCOMES = REJECTIONS + ("no_thumb_contact", "open_finger_collides", "few_contacts", "not_closed", "closed")


@dataclass(frozen=True)
class SearchParams:
    """The per-frame search and scoring settings (a subset of the grasp-list parameters)."""

    mu: float
    cone_edges: int
    ik_tolerance: float
    ik_iterations: int
    contact_clearance: float
    max_candidates: int
    ik_batch: int
    press_angle: float


@dataclass(frozen=True)
class FrameGrasp:
    """What one grasp frame gave: its outcome and, for a grasp with >= 3 contacts, the grasp and its scores."""

    outcome: str
    hand_pose: np.ndarray | None = None
    finger_q: np.ndarray | None = None
    contact_index: np.ndarray | None = None  # (f,) object point per finger, -1: no contact
    epsilon: float = 0.0
    com_distance: float = 0.0
    com_score: float = 0.0
    ellipsoid: float = 0.0
    curvature: float = 0.0


@dataclass
class Placed:
    """The shapes of the fingers placed so far, per frame: each frame searched on has those of the same fingers."""

    shapes: list[list[Posed]]  # per frame
    centres: np.ndarray  # (n, p, 3): their bounding spheres' centres, per frame
    radii: np.ndarray  # (p,)

    def add(self, posed: dict[int, list[Posed]], radii: np.ndarray) -> None:
        """One more finger's shapes (`radii` their bounding spheres'), posed in the frames that go on."""
        centres = np.zeros((len(self.shapes), len(radii), 3))
        for k, shapes in posed.items():
            self.shapes[k] = self.shapes[k] + shapes
            centres[k] = [s.centre for s in shapes]
        self.centres, self.radii = np.concatenate([self.centres, centres], axis=1), np.r_[self.radii, radii]


def closing_direction(finger: FingerChain) -> np.ndarray:
    """Per joint, the sign in which the finger closes: from its open configuration towards mid-range (0 when open is mid-range)."""
    mid, span = 0.5 * (finger.lower + finger.upper), finger.upper - finger.lower
    return np.where(np.abs(mid - finger.open_q) > 0.1 * span, np.sign(mid - finger.open_q), 0.0)


class GraspSearch:
    """Computes the grasps at grasp frames for one hand and one object (read-only after construction)."""

    def __init__(self, hand: HandModel, workspaces: tuple[FingerWorkspace, ...], obj: ObjectModel,
                 mesh: trimesh.Trimesh, p: SearchParams, limit_margin: float):
        self.hand, self.workspaces, self.obj, self.p = hand, workspaces, obj, p
        self.test = ObjectTest(mesh)
        self.triangles = np.asarray(mesh.triangles, float)
        self.screen = ObjectScreen(obj.tree, self.triangles, obj.step)
        self.seeds = [w.seeds() for w in workspaces]
        self.limits = [f.reduced_limits(limit_margin) for f in hand.fingers]
        self.torque_scale = obj.radius
        self.tip_spheres = [sphere(f.tip_radius - p.contact_clearance) for f in hand.fingers]
        self.targets = [obj.points + f.tip_radius * obj.normals for f in hand.fingers]
        self.closing = [closing_direction(f) for f in hand.fingers]
        self.finders = [CandidateFinder(w, t, obj.tree) for w, t in zip(workspaces, self.targets)]
        self.body_inside = [inside_of(s.geometry) for s in hand.body]
        # per finger and shape, what the screen tests of what is tested against the object, touching (the shrunk tip) or
        # open: the shapes on the last link, where a finger whose tip touches the object most often hits it too
        self.inside = [{touching: [inside_of(self._probe(fi, s, touching)) if s.link == f.dof - 1 else None for s in f.shapes]
                        for touching in (True, False)} for fi, f in enumerate(hand.fingers)]
        self.open_poses = [f.shape_poses(f.open_q[None])[0] for f in hand.fingers]
        # per finger, its shapes' bounding spheres in their own frames: centres (s, 3) and radii (s,)
        spheres = [[bounding(s.geometry, np.eye(4)) for s in f.shapes] for f in hand.fingers]
        self.test_order = [sorted(range(len(f.shapes)), key=lambda j, f=f: (f.shapes[j].is_tip, -f.shapes[j].link)) for f in hand.fingers]
        self.bounds = [(np.array([c for c, _ in b]).reshape(-1, 3), np.array([r for _, r in b])) for b in spheres]
        # per finger and touching or open, the radii screened for clearance (a touching fingertip never is: inf)
        self.screened = [{touching: np.where([touching and s.is_tip for s in f.shapes], np.inf, radii)
                          for touching in (True, False)} for f, (_, radii) in zip(hand.fingers, self.bounds)]

    def _probe(self, fi: int, shape, touching: bool) -> Geometry:
        """What a finger shape is tested against the object as: a touching fingertip shrunk by the clearance."""
        return self.tip_spheres[fi] if (touching and shape.is_tip) else shape.geometry

    def _fits(self, fi: int, world: np.ndarray, centres: np.ndarray, clear: np.ndarray, near: np.ndarray,
              placed: list[Posed], touching: bool) -> list[Posed] | None:
        """The finger's shapes (posed in the object frame, `world` (s, 4, 4), bounding spheres at `centres` (s, 3)) when
        collision-free with the object and the placed shapes, else None. Coal tests the object for the shapes the
        screen does not show `clear` of it, links nearest the fingertip first (the likeliest to touch it), then the
        pairs of a shape and a placed one whose bounding spheres are `near` (s, len(placed))."""
        shapes, test = self.hand.fingers[fi].shapes, self.test
        transforms: list = [None] * len(shapes)
        for j in self.test_order[fi]:
            if clear[j]:
                continue
            transforms[j] = transform3s(world[j])
            if test.hits_object(self._probe(fi, shapes[j], touching), transforms[j]):
                return None
        for j, o in zip(*np.nonzero(near)):
            if transforms[j] is None:
                transforms[j] = transform3s(world[j])
            if test.hits_placed((shapes[j].geometry, transforms[j]), [(placed[o].geometry, placed[o].transform())]):
                return None
        return [Posed(shape.geometry, pose, centre, float(r), tf)
                for shape, pose, centre, r, tf in zip(shapes, world, centres, self.bounds[fi][1], transforms)]

    def _screened(self, fi: int, world: np.ndarray, frames: np.ndarray, placed: Placed,
                  touching: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For a finger posed at `world` (m, s, 4, 4) in `frames` (m,): its shapes' bounding-sphere centres (m, s, 3),
        which shapes are certainly clear of the object (m, s) and which pairs of a shape and a placed one have
        bounding spheres near enough to meet (m, s, placed)."""
        centres = np.einsum("msij,sj->msi", world[..., :3, :3], self.bounds[fi][0]) + world[..., :3, 3]
        clear = self.screen.clear(centres, self.screened[fi][touching])
        reach = self.bounds[fi][1][:, None] + placed.radii + SPHERE_MARGIN
        near = np.linalg.norm(centres[:, :, None] - placed.centres[frames][:, None], axis=3) <= reach
        return centres, clear, near

    def _presses(self, fi: int, J: np.ndarray, normals: np.ndarray) -> np.ndarray:
        """Which contacts the finger can press, by its fingertip Jacobians J (m, 3, k): closing it (joints moving from
        the open configuration towards mid-range) moves the fingertip into the surface, within `press_angle` of the
        inward normal."""
        motion = J @ self.closing[fi]
        norm = np.linalg.norm(motion, axis=1)
        return -np.einsum("ij,ij->i", motion, normals) > np.cos(self.p.press_angle) * np.maximum(norm, 1e-12)

    def _ranked(self, c: Candidates, contact: np.ndarray) -> tuple[Candidates, np.ndarray]:
        """A finger's candidates in the order it tries them, at most `max_candidates` per frame, and their ranks."""
        placed = np.where(contact[:, :, None] >= 0, self.obj.normals[np.maximum(contact, 0)], 0.0).sum(axis=1)
        opposed = placed.any(axis=1)[c.frame]
        key = np.where(opposed, np.einsum("ij,ij->i", self.obj.normals[c.point], placed[c.frame]), c.centre_distance)
        return c.ranked(key, self.p.max_candidates)

    def _place_finger(self, fi: int, H: np.ndarray, c: Candidates, contact: np.ndarray,
                      placed: Placed) -> dict[int, tuple[np.ndarray, int, list[Posed]]]:
        """Per frame of the candidates, the finger's first collision-free contact: frame -> (q, point index, posed shapes)."""
        finger, p = self.hand.fingers[fi], self.p
        c, rank = self._ranked(c, contact)
        lower, upper = self.limits[fi]
        found: dict[int, tuple[np.ndarray, int, list[Posed]]] = {}
        done = np.zeros(len(H), bool)
        for start in range(0, p.max_candidates, p.ik_batch):
            rows = np.flatnonzero((rank >= start) & (rank < start + p.ik_batch) & ~done[c.frame])
            if len(rows) == 0:
                break
            frame, point = c.frame[rows], c.point[rows]
            R = H[frame, :3, :3]
            targets = np.einsum("ki,kij->kj", self.targets[fi][point] - H[frame, :3, 3], R)
            _, seed = self.seeds[fi].query(targets)
            q, err, J = finger.ik(targets, self.workspaces[fi].seed_q[seed], lower, upper, p.ik_tolerance,
                                  p.ik_iterations, groups=frame)
            ok = np.flatnonzero(err < p.ik_tolerance)
            ok = ok[self._presses(fi, J[ok], np.einsum("ki,kij->kj", self.obj.normals[point[ok]], R[ok]))]
            if len(ok) == 0:
                continue
            world = H[frame[ok], None] @ finger.shape_poses(q[ok])
            tried = np.flatnonzero(~self.screen.hits(world, self.inside[fi][True]))
            screens = self._screened(fi, world[tried], frame[ok[tried]], placed, touching=True)
            for j, centres, clear, near in zip(tried, *screens):
                k = ok[j]
                if done[frame[k]]:
                    continue
                posed = self._fits(fi, world[j], centres, clear, near, placed.shapes[frame[k]], touching=True)
                if posed is not None:
                    found[int(frame[k])] = (q[k], int(point[k]), posed)
                    done[frame[k]] = True
        return found

    def _open_fits(self, fi: int, H: np.ndarray, frames: np.ndarray, placed: Placed) -> list[list[Posed] | None]:
        """Per frame, the finger's posed shapes when it stays open and is collision-free there, else None."""
        world = H[frames, None] @ self.open_poses[fi]
        sure = self.screen.hits(world, self.inside[fi][False])
        return [None if s else self._fits(fi, w, *screens, placed.shapes[k], touching=False)
                for k, w, s, *screens in zip(frames, world, sure, *self._screened(fi, world, frames, placed, touching=False))]

    def grasps(self, H: np.ndarray) -> list[FrameGrasp]:
        """The grasp (or why none) at each hand pose of H (n, 4, 4: the hand frame in the object frame)."""
        outcome, candidates = rejected(self, H)
        n, f = len(H), len(self.hand.fingers)
        alive = np.flatnonzero(outcome == "")
        q = np.tile(self.hand.open_q, (n, 1))
        ends = np.cumsum([finger.dof for finger in self.hand.fingers])
        contact = -np.ones((n, f), int)
        placed = Placed([[] for _ in range(n)], np.zeros((n, 0, 3)), np.zeros(0))
        for rank, fi in enumerate(self.hand.thumb_first):
            mine = candidates[fi]
            member = np.zeros(n, bool)
            member[alive] = True
            found = self._place_finger(fi, H, mine.subset(member[mine.frame]), contact, placed)
            posed_now = {k: posed for k, (_, _, posed) in found.items()}
            for k, (qf, point, _) in found.items():
                q[k, ends[fi] - len(qf):ends[fi]], contact[k, fi] = qf, point
            missing = np.array([k for k in alive if k not in found], int)
            if rank == 0:
                outcome[missing] = "no_thumb_contact"
            else:
                for k, posed in zip(missing, self._open_fits(fi, H, missing, placed)):
                    if posed is None:
                        outcome[k] = "open_finger_collides"
                    else:
                        posed_now[k] = posed
            placed.add(posed_now, self.bounds[fi][1])
            alive = alive[outcome[alive] == ""]
            few = np.count_nonzero(contact[alive] >= 0, axis=1) + (f - rank - 1) < MIN_CONTACTS
            outcome[alive[few]] = "few_contacts"
            alive = alive[~few]
        scored = self._scored(H, q, contact, alive)
        return [scored[k] if k in scored else FrameGrasp(outcome[k]) for k in range(n)]

    def _scored(self, H: np.ndarray, q: np.ndarray, contact: np.ndarray, frames: np.ndarray) -> dict[int, FrameGrasp]:
        """Stability filter and scores of the grasps with enough contacts, by frame."""
        p, obj = self.p, self.obj
        used = [np.flatnonzero(contact[k] >= 0) for k in frames]
        wrenches: list = [None] * len(frames)
        counts = np.array([len(u) for u in used], int)
        for c in np.unique(counts):  # the grasps of c contacts together
            rows = np.flatnonzero(counts == c)
            index = np.array([contact[frames[r], used[r]] for r in rows])
            for r, w in zip(rows, contact_wrenches(obj.points[index], obj.normals[index], obj.com, p.mu, p.cone_edges,
                                                   self.torque_scale)):
                wrenches[r] = w
        out = {}
        for k, u, w, apart_ in zip(frames, used, wrenches, separated(wrenches)):
            closed, eps = (False, 0.0) if apart_ else wrench_closure(w)
            if not closed:
                out[int(k)] = FrameGrasp("not_closed")
                continue
            points, parts, alignment = obj.points[contact[k, u]], self.hand.split(q[k]), []
            for fi in u:
                _, J = self.hand.fingers[fi].jacobians(parts[fi][None])
                alignment.append(ellipsoid_alignment(J[0], H[k, :3, :3].T @ obj.normals[contact[k, fi]]))
            radius = min(self.hand.fingers[fi].tip_radius for fi in u)
            d, s = com_score(points, obj.com, self.torque_scale)
            out[int(k)] = FrameGrasp("closed", H[k], q[k].copy(), contact[k].copy(), eps, d, s, float(np.mean(alignment)),
                                     curvature_score(obj.curvature[contact[k, u]], radius))
        return out
