"""The grasp at one grasp frame (paper IV-A.2): finger by finger, thumb first, contacts from sphere hierarchy x kd-tree.

For each finger, its workspace spheres (largest first) are moved into the object frame and
intersected with the object's point set; a candidate contact p with outward normal n asks the
fingertip sphere (radius r) to sit at p + r n. Within one sphere (the paper leaves the order
open) the thumb takes the point nearest the sphere's centre first, the other fingers the surface
most opposed to the contacts already made (force closure needs opposition). The candidates' IK
is solved in batches, seeded from the nearest workspace sample; a solution counts when closing
the finger pushes its tip into the surface (within `press_angle` of the inward normal: a finger
can only squeeze by closing), and the first candidate whose finger is collision-free with
the object (the fingertip sphere shrunk by a clearance, since it touches) and with the fingers
already placed is accepted. A finger without contact stays open and must be collision-free too;
the hand body must not touch the object. Contacts >= 3 go to the stability filter.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from planner.collision.hand_placement import ObjectTest
from planner.collision.shapes import sphere
from planner.grasping.finger_workspace import FingerWorkspace
from planner.grasping.object_model import ObjectModel
from planner.grasping.quality import com_score, curvature_score, ellipsoid_alignment, force_closure
from planner.model.hand_model import FingerChain, HandModel

MIN_CONTACTS = 3
# Why a frame yields no grasp (or the grasp it yields), in the order the search meets them.
OUTCOMES = ("body_collides", "no_thumb_contact", "open_finger_collides", "few_contacts", "not_closed", "closed")


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


def closing_direction(finger: FingerChain) -> np.ndarray:
    """Per joint, the sign in which the finger closes: from its open configuration towards mid-range (0 when open is mid-range)."""
    mid, span = 0.5 * (finger.lower + finger.upper), finger.upper - finger.lower
    return np.where(np.abs(mid - finger.open_q) > 0.1 * span, np.sign(mid - finger.open_q), 0.0)


class GraspSearch:
    """Computes the grasp at grasp frames for one hand and one object (read-only after construction)."""

    def __init__(self, hand: HandModel, workspaces: tuple[FingerWorkspace, ...], obj: ObjectModel,
                 mesh: trimesh.Trimesh, p: SearchParams, limit_margin: float):
        self.hand, self.workspaces, self.obj, self.p = hand, workspaces, obj, p
        self.test = ObjectTest(mesh)
        self.seeds = [w.seeds() for w in workspaces]
        self.limits = [f.reduced_limits(limit_margin) for f in hand.fingers]
        self.torque_scale = obj.radius
        self.tip_spheres = [sphere(f.tip_radius - p.contact_clearance) for f in hand.fingers]
        self.targets = [obj.points + f.tip_radius * obj.normals for f in hand.fingers]
        self.closing = [closing_direction(f) for f in hand.fingers]

    def _finger_fits(self, fi: int, shape_poses: np.ndarray, H: np.ndarray, placed: list, touching: bool) -> list | None:
        """The finger's shapes posed in the object frame when collision-free with the object and placed fingers, else None."""
        finger = self.hand.fingers[fi]
        posed = []
        for shape, pose in zip(finger.shapes, shape_poses):
            world = H @ pose
            probe = self.tip_spheres[fi] if (touching and shape.is_tip) else shape.geometry
            if self.test.hits_object(probe, world):
                return None
            placed_shape = self.test.posed(shape.geometry, world)
            if self.test.hits_placed(placed_shape, placed):
                return None
            posed.append(placed_shape)
        return posed

    def candidates(self, fi: int, H: np.ndarray, placed_normals: np.ndarray) -> np.ndarray:
        """Object points whose fingertip target lies in the finger's spheres, largest sphere first; within a sphere,
        the surface most opposed to the contacts already made first (the thumb's: nearest the centre first)."""
        ws, finger = self.workspaces[fi], self.hand.fingers[fi]
        centres = ws.centres @ H[:3, :3].T + H[:3, 3]
        idx = np.asarray(self.obj.tree.query_ball_point(H[:3, :3] @ ws.centre + H[:3, 3], ws.reach + finger.tip_radius), int)
        if len(idx) == 0:
            return idx
        targets = self.targets[fi][idx]
        inside = np.linalg.norm(targets[:, None, :] - centres[None], axis=2) <= ws.radii
        sphere = np.argmax(inside, axis=1)  # the largest sphere holding the target
        hit = inside[np.arange(len(idx)), sphere]
        idx, sphere = idx[hit], sphere[hit]
        if placed_normals.any():
            key = self.obj.normals[idx] @ placed_normals
        else:
            key = np.linalg.norm(targets[hit] - centres[sphere], axis=1)
        return idx[np.lexsort((key, sphere))][: self.p.max_candidates]

    def _presses(self, fi: int, q: np.ndarray, normals: np.ndarray) -> np.ndarray:
        """Which contacts the finger can press: closing it (joints moving from the open configuration towards
        mid-range) moves the fingertip into the surface, within `press_angle` of the inward normal."""
        finger = self.hand.fingers[fi]
        _, J = finger.jacobians(q)
        motion = J @ self.closing[fi]
        norm = np.linalg.norm(motion, axis=1)
        return -np.einsum("ij,ij->i", motion, normals) > np.cos(self.p.press_angle) * np.maximum(norm, 1e-12)

    def _place_finger(self, fi: int, H: np.ndarray, placed: list, placed_normals: np.ndarray) -> tuple[np.ndarray, int, list] | None:
        """The first collision-free contact of a finger: (q, point index, posed shapes), or None."""
        finger = self.hand.fingers[fi]
        cand = self.candidates(fi, H, placed_normals)
        lower, upper = self.limits[fi]
        R, t = H[:3, :3], H[:3, 3]
        for start in range(0, len(cand), self.p.ik_batch):
            batch = cand[start:start + self.p.ik_batch]
            targets = (self.targets[fi][batch] - t) @ R
            _, seed = self.seeds[fi].query(targets)
            q, err = finger.ik(targets, self.workspaces[fi].seed_q[seed], lower, upper, self.p.ik_tolerance, self.p.ik_iterations)
            ok = np.flatnonzero(err < self.p.ik_tolerance)
            ok = ok[self._presses(fi, q[ok], self.obj.normals[batch[ok]] @ R)]
            if len(ok) == 0:
                continue
            poses = finger.shape_poses(q[ok])
            for j, k in enumerate(ok):
                posed = self._finger_fits(fi, poses[j], H, placed, touching=True)
                if posed is not None:
                    return q[k], int(batch[k]), posed
        return None

    def at_frame(self, H: np.ndarray) -> FrameGrasp:
        """The grasp at hand pose H (hand frame in the object frame), finger by finger, thumb first."""
        for shape in self.hand.body:
            if self.test.hits_object(shape.geometry, H @ shape.placement):
                return FrameGrasp("body_collides")
        n = len(self.hand.fingers)
        qs = [f.open_q for f in self.hand.fingers]
        contact = -np.ones(n, int)
        placed: list = []
        for rank, fi in enumerate(self.hand.thumb_first):
            found = self._place_finger(fi, H, placed, self.obj.normals[contact[contact >= 0]].sum(0))
            if found is None:
                if rank == 0:
                    return FrameGrasp("no_thumb_contact")
                finger = self.hand.fingers[fi]
                posed = self._finger_fits(fi, finger.shape_poses(finger.open_q[None])[0], H, placed, touching=False)
                if posed is None:
                    return FrameGrasp("open_finger_collides")
            else:
                qs[fi], contact[fi], posed = found
            placed += posed
            if np.count_nonzero(contact >= 0) + (n - rank - 1) < MIN_CONTACTS:
                return FrameGrasp("few_contacts")
        return self._scored(H, np.concatenate(qs), contact)

    def _scored(self, H: np.ndarray, q: np.ndarray, contact: np.ndarray) -> FrameGrasp:
        """Stability filter and scores of a grasp with enough contacts."""
        used = np.flatnonzero(contact >= 0)
        points, normals = self.obj.points[contact[used]], self.obj.normals[contact[used]]
        closed, eps = force_closure(points, normals, self.obj.com, self.p.mu, self.p.cone_edges, self.torque_scale)
        if not closed:
            return FrameGrasp("not_closed")
        parts, alignment = self.hand.split(q), []
        for fi in used:
            _, J = self.hand.fingers[fi].jacobians(parts[fi][None])
            alignment.append(ellipsoid_alignment(J[0], H[:3, :3].T @ self.obj.normals[contact[fi]]))
        radius = min(self.hand.fingers[fi].tip_radius for fi in used)
        d, s = com_score(points, self.obj.com, self.torque_scale)
        return FrameGrasp("closed", H, q, contact, eps, d, s, float(np.mean(alignment)),
                          curvature_score(self.obj.curvature[contact[used]], radius))
