"""The object model (paper IV-A.2, fig. 2): the surface as an even point set with normals, mean curvature and a kd-tree.

Points are sampled on the surface at least `step` apart (the step derives from the fingertip
radius), each with its face's outward normal and the mesh's discrete mean curvature interpolated
from the vertices (edge-length times dihedral angle, Steiner's formula; trimesh's ball measure
needs rtree, which is not a dependency). A kd-tree partitions the points; its leaves are exposed
for drawing. Cached per mesh and step.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from planner.core.user_cache import building, cache_key, cache_path, load_arrays, save_arrays

CODE_VERSION = "object-model-1"
LEAF_SIZE = 16
SAMPLING_SEED = 0  # the point set depends on the mesh only, never on a session's seed


@dataclass(frozen=True, eq=False)
class ObjectModel:
    """Surface points (object frame), outward unit normals, mean curvature (1/m) and a kd-tree over the points."""

    points: np.ndarray  # (m, 3)
    normals: np.ndarray  # (m, 3)
    curvature: np.ndarray  # (m,) signed mean curvature, positive where convex
    com: np.ndarray  # (3,) centre of mass
    radius: float  # m: largest distance from the centre of mass to a vertex
    step: float

    @functools.cached_property
    def tree(self) -> cKDTree:
        return cKDTree(self.points, leafsize=LEAF_SIZE)

    def leaf_ids(self) -> np.ndarray:
        """(m,) the kd-tree leaf holding each point (leaves numbered left to right), for drawing fig. 2."""
        out = np.empty(len(self.points), int)
        stack, leaf = [self.tree.tree], 0
        while stack:
            node = stack.pop()
            if node.greater is None:
                out[node.indices] = leaf
                leaf += 1
            else:
                stack += [node.greater, node.lesser]
        return out


def vertex_mean_curvature(mesh: trimesh.Trimesh) -> np.ndarray:
    """Discrete mean curvature per vertex: a quarter of |edge| x signed dihedral angle per incident edge, over a third of
    the incident area."""
    edges = mesh.face_adjacency_edges
    angles = mesh.face_adjacency_angles * np.where(mesh.face_adjacency_convex, 1.0, -1.0)
    lengths = np.linalg.norm(mesh.vertices[edges[:, 0]] - mesh.vertices[edges[:, 1]], axis=1)
    measure = np.zeros(len(mesh.vertices))
    np.add.at(measure, edges.ravel(), np.repeat(0.25 * lengths * angles, 2))
    area = np.zeros(len(mesh.vertices))
    np.add.at(area, mesh.faces.ravel(), np.repeat(mesh.area_faces / 3.0, 3))
    return measure / np.maximum(area, 1e-12)


def _thinned(points: np.ndarray, step: float) -> np.ndarray:
    """Indices of a greedy subset of the points in which no two are closer than `step` (Poisson-disk thinning)."""
    removed = np.zeros(len(points), bool)
    keep = []
    for i, near in enumerate(cKDTree(points).query_ball_point(points, step)):
        if not removed[i]:
            keep.append(i)
            removed[near] = True
    return np.asarray(keep, int)


def build_object_model(mesh: trimesh.Trimesh, step: float) -> ObjectModel:
    """Sample the surface evenly with spacing `step` and attach normals and curvature."""
    count = int(np.ceil(8.0 * mesh.area / step**2))
    points, faces = trimesh.sample.sample_surface(mesh, count, seed=SAMPLING_SEED)
    keep = _thinned(points, step)
    points, faces = points[keep], faces[keep]
    bary = trimesh.triangles.points_to_barycentric(mesh.triangles[faces], points)
    curvature = np.einsum("ij,ij->i", bary, vertex_mean_curvature(mesh)[mesh.faces[faces]])
    com = np.asarray(mesh.center_mass, float)
    radius = float(np.linalg.norm(mesh.vertices - com, axis=1).max())
    return ObjectModel(np.asarray(points, float), np.asarray(mesh.face_normals[faces], float), curvature, com, radius, step)


def mesh_bytes(mesh: trimesh.Trimesh) -> bytes:
    """The mesh's geometry as bytes: part of every cache key that depends on the object."""
    return np.ascontiguousarray(mesh.vertices, np.float64).tobytes() + np.ascontiguousarray(mesh.faces, np.int64).tobytes()


def object_model(mesh: trimesh.Trimesh, step: float) -> ObjectModel:
    """The object model of a mesh, from the user cache when this mesh and step were seen."""
    path = cache_path("objects", cache_key(CODE_VERSION, mesh_bytes(mesh), repr(step)) + ".npz")
    z = load_arrays(path)
    if z is not None:
        return ObjectModel(z["points"], z["normals"], z["curvature"], z["com"], float(z["radius"]), step)
    with building(f"the object model of a mesh of {len(mesh.faces):,} faces (entry {path.stem})"):
        model = build_object_model(mesh, step)
        save_arrays(path, {"points": model.points, "normals": model.normals, "curvature": model.curvature,
                           "com": model.com, "radius": np.float64(model.radius)})
    return model
