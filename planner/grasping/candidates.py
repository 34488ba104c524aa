"""One finger's contact candidates at many grasp frames at once (paper IV-A.2: workspace spheres x the object's kd-tree).

A candidate is an object point whose fingertip target (the point pushed out along its normal by the
fingertip radius) lies in one of the finger's workspace spheres (the spheres are disjoint: the
hierarchy puts each next centre outside the spheres before it), tagged with that sphere. Per sphere,
one query between a kd-tree over its centres in every frame and one over the targets finds them all.
A frame's candidates come in the order in which the object's own kd-tree lists the points (ties in a
ranking keep it).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from planner.grasping.finger_workspace import FingerWorkspace


@dataclass(frozen=True, eq=False)
class Candidates:
    """(frame, point) pairs, frames non-decreasing, each with its sphere and the target's distance to that sphere's centre."""

    frame: np.ndarray  # (k,) index into the frames
    point: np.ndarray  # (k,) object point
    sphere: np.ndarray  # (k,) index of the largest workspace sphere holding the target
    centre_distance: np.ndarray  # (k,) m

    def subset(self, keep: np.ndarray) -> Candidates:
        """The pairs selected by a boolean mask or an index array (in its order)."""
        return Candidates(self.frame[keep], self.point[keep], self.sphere[keep], self.centre_distance[keep])

    def renumbered(self, frames: np.ndarray) -> Candidates:
        """The pairs with frame i renamed frames[i] (candidates of a subset of the frames, named in the whole)."""
        return Candidates(frames[self.frame], self.point, self.sphere, self.centre_distance)

    def counts(self, frames: int) -> np.ndarray:
        """(frames,) how many candidates each frame has."""
        return np.bincount(self.frame, minlength=frames)

    def ranked(self, key: np.ndarray, limit: int) -> tuple[Candidates, np.ndarray]:
        """Per frame, the pairs by sphere (largest first) then `key` (ties keep their order), at most `limit` of them;
        and each kept pair's rank within its frame."""
        order = np.lexsort((key, self.sphere, self.frame))
        frame = self.frame[order]
        first = np.flatnonzero(np.r_[True, frame[1:] != frame[:-1]]) if len(frame) else np.zeros(0, int)
        rank = np.arange(len(frame)) - np.repeat(first, np.diff(np.r_[first, len(frame)]))
        keep = rank < limit
        return self.subset(order[keep]), rank[keep]


class CandidateFinder:
    """One finger's candidate search: its workspace, the fingertip targets of the object's points and a kd-tree over them."""

    def __init__(self, ws: FingerWorkspace, targets: np.ndarray, point_tree: cKDTree):
        self.ws, self.targets = ws, targets
        self.tree = cKDTree(targets)
        self.position = np.empty(len(targets), int)  # each point's place in the object kd-tree's order
        self.position[point_tree.indices] = np.arange(len(targets))

    def __call__(self, H: np.ndarray) -> Candidates:
        """Every frame's candidates; `H` (n, 4, 4) are the hand poses in the object frame."""
        ws = self.ws
        centres = ws.centres @ H[:, :3, :3].transpose(0, 2, 1) + H[:, None, :3, 3]  # (n, s, 3): the spheres, object frame
        # per sphere, the (frame, point) pairs within its radius: two kd-trees, pairs as arrays (no list per query)
        pairs = [cKDTree(centres[:, j]).sparse_distance_matrix(self.tree, r, output_type="ndarray") if len(H) else
                 np.zeros(0, [("i", int), ("j", int)]) for j, r in enumerate(ws.radii)]
        frame = np.concatenate([p["i"] for p in pairs] + [np.zeros(0, int)]).astype(int)
        point = np.concatenate([p["j"] for p in pairs] + [np.zeros(0, int)]).astype(int)
        sphere = np.repeat(np.arange(len(pairs)), [len(p) for p in pairs]).astype(int)
        order = np.lexsort((self.position[point], frame))
        frame, sphere, point = frame[order], sphere[order], point[order]
        distance = np.linalg.norm(self.targets[point] - centres[frame, sphere], axis=1)
        return Candidates(frame, point, sphere, distance)
