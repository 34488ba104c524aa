"""Finger workspaces (paper IV-A.2, fig. 3): a voxel grid of fingertip positions and its sphere hierarchy.

The fingertip workspace is sampled on a grid of joint values within slightly reduced limits (no
stretched fingers), voxelised and closed; voxels are boundary (a face-neighbour is outside) or
inner. Spheres are placed greedily: the inner point farthest from the boundary is the first centre,
distances are updated with the new sphere and the next farthest taken, until a maximum count or a
minimum radius. The order is kept, largest first. The joint samples also seed the finger IK.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from planner.core.user_cache import building, cache_key, cache_path, load_arrays, save_arrays
from planner.model.hand_model import FingerChain, HandModel

CODE_VERSION = "workspace-1"


@dataclass(frozen=True)
class WorkspaceParams:
    """How finger workspaces are approximated; part of the cache key."""

    limit_margin: float = 0.1  # fraction of each joint range cut off at both ends
    samples_per_joint: int = 14  # joint-space grid resolution
    voxel: float = 0.004  # m: workspace grid step
    max_spheres: int = 40
    min_radius: float = 0.006  # m: stop when the next sphere would be smaller


@dataclass(frozen=True, eq=False)
class FingerWorkspace:
    """One finger's workspace grid, its sphere hierarchy (hand frame) and IK seeds."""

    origin: np.ndarray  # (3,) centre of voxel (0, 0, 0)
    voxel: float
    occupied: np.ndarray  # (nx, ny, nz) bool
    boundary: np.ndarray  # (nx, ny, nz) bool, subset of occupied
    centres: np.ndarray  # (s, 3), largest sphere first
    radii: np.ndarray  # (s,)
    seed_q: np.ndarray  # (m, k) joint samples
    seed_tips: np.ndarray  # (m, 3) their fingertip positions

    def points(self, mask: np.ndarray) -> np.ndarray:
        """Hand-frame centres of the voxels set in `mask`."""
        return self.origin + np.argwhere(mask) * self.voxel

    @functools.cached_property
    def centre(self) -> np.ndarray:
        """The centre of the ball (radius `reach`) that holds every sphere of the hierarchy."""
        return 0.5 * (np.min(self.centres - self.radii[:, None], 0) + np.max(self.centres + self.radii[:, None], 0))

    @functools.cached_property
    def reach(self) -> float:
        return float(np.max(np.linalg.norm(self.centres - self.centre, axis=1) + self.radii))

    def seeds(self) -> cKDTree:
        return cKDTree(self.seed_tips)


def sphere_hierarchy(inner: np.ndarray, boundary: np.ndarray, max_spheres: int, min_radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Greedy spheres inside a point-sampled volume: centres (s, 3) and radii (s,), non-increasing."""
    if len(inner) == 0 or len(boundary) == 0:
        return np.zeros((0, 3)), np.zeros(0)
    d, _ = cKDTree(boundary).query(inner)
    alive = np.ones(len(inner), bool)
    centres, radii = [], []
    while len(centres) < max_spheres and alive.any():
        i = int(np.argmax(np.where(alive, d, -np.inf)))
        r = float(d[i])
        if r < min_radius:
            break
        c = inner[i]
        centres.append(c)
        radii.append(r)
        gap = np.linalg.norm(inner - c, axis=1) - r
        alive &= gap > 0
        d = np.minimum(d, gap)
    return np.asarray(centres).reshape(-1, 3), np.asarray(radii)


def finger_workspace(finger: FingerChain, p: WorkspaceParams) -> FingerWorkspace:
    """Sample, voxelise, classify and fill one finger's fingertip workspace."""
    lo, hi = finger.reduced_limits(p.limit_margin)
    axes = [np.linspace(a, b, p.samples_per_joint) for a, b in zip(lo, hi)]
    q = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, finger.dof)
    tips = finger.tip_positions(q)
    origin = tips.min(0) - p.voxel
    cells = np.round((tips - origin) / p.voxel).astype(int)
    shape = tuple(cells.max(0) + 2)
    grid = np.zeros(shape, bool)
    grid[tuple(cells.T)] = True
    grid = ndimage.binary_fill_holes(ndimage.binary_closing(grid, iterations=2))
    boundary = grid & ~ndimage.binary_erosion(grid, border_value=0)
    ws = FingerWorkspace(origin, p.voxel, grid, boundary, np.zeros((0, 3)), np.zeros(0), q, tips)
    centres, radii = sphere_hierarchy(ws.points(grid & ~boundary), ws.points(boundary), p.max_spheres, p.min_radius)
    return FingerWorkspace(origin, p.voxel, grid, boundary, centres, radii, q, tips)


_FIELDS = ("origin", "occupied", "boundary", "centres", "radii", "seed_q", "seed_tips")


def hand_workspaces(hand: HandModel, p: WorkspaceParams = WorkspaceParams()) -> tuple[FingerWorkspace, ...]:
    """Every finger's workspace (spec order), from the user cache when this hand and these parameters were seen."""
    path = cache_path("workspaces", cache_key(CODE_VERSION, repr(hand.spec), hand.spec.urdf.read_bytes(), repr(p)) + ".npz")
    z = load_arrays(path)
    if z is not None:
        return tuple(FingerWorkspace(voxel=p.voxel, **{f: z[f"{i}/{f}"] for f in _FIELDS}) for i in range(len(hand.fingers)))
    with building(f"the finger workspaces of the hand {hand.spec.urdf.name} (entry {path.stem})"):
        out = tuple(finger_workspace(f, p) for f in hand.fingers)
        save_arrays(path, {f"{i}/{f}": getattr(w, f) for i, w in enumerate(out) for f in _FIELDS})
    return out
