"""Small geometry helpers: poses, coal shapes from trimesh meshes, conservative simplified hulls."""
from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
import trimesh


def pose(xyz=(0.0, 0.0, 0.0), rpy=(0.0, 0.0, 0.0)) -> np.ndarray:
    """4x4 homogeneous transform from a translation and roll-pitch-yaw angles."""
    T = np.eye(4)
    T[:3, :3] = pin.rpy.rpyToMatrix(*map(float, rpy))
    T[:3, 3] = xyz
    return T


def se3(T: np.ndarray) -> pin.SE3:
    return pin.SE3(np.asarray(T[:3, :3], float), np.asarray(T[:3, 3], float))


def transform3s(T: np.ndarray) -> coal.Transform3s:
    return coal.Transform3s(np.asarray(T[:3, :3], float), np.asarray(T[:3, 3], float))


def fibonacci_sphere(n: int) -> np.ndarray:
    """n nearly uniform unit directions."""
    i = np.arange(n) + 0.5
    phi = np.arccos(1.0 - 2.0 * i / n)
    theta = np.pi * (1.0 + 5.0**0.5) * i
    return np.c_[np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)]


def coal_convex(mesh: trimesh.Trimesh) -> coal.Convex:
    """A coal.Convex from a convex trimesh (coal here has no qhull: the hull is computed by trimesh)."""
    pts = coal.StdVec_Vec3s()
    for p in np.asarray(mesh.vertices, dtype=float):
        pts.append(p)
    tris = coal.StdVec_Triangle()
    for f in np.asarray(mesh.faces):
        tris.append(coal.Triangle(int(f[0]), int(f[1]), int(f[2])))
    return coal.Convex(pts, tris)


def coal_mesh(mesh: trimesh.Trimesh) -> coal.BVHModelOBBRSS:
    """An exact (non-convex) coal BVH model of a triangle mesh."""
    bvh = coal.BVHModelOBBRSS()
    bvh.beginModel(len(mesh.faces), len(mesh.vertices))
    bvh.addVertices(np.asarray(mesh.vertices, dtype=float))
    bvh.addTriangles(np.asarray(mesh.faces, dtype=np.int64))
    bvh.endModel()
    return bvh


def simplified_hull(vertices: np.ndarray, tolerance: float, max_directions: int = 512) -> tuple[trimesh.Trimesh, float]:
    """A hull of few vertices plus the radius that makes it conservative.

    Takes the true hull's support points in more and more directions until every true-hull vertex
    lies within `tolerance` of the small hull; returns the small hull and that largest distance,
    used as a swept-sphere radius so the shape always contains the original mesh.
    """
    hull = trimesh.convex.convex_hull(np.asarray(vertices, dtype=float))
    n = 48
    while True:
        support = np.unique(np.argmax(hull.vertices @ fibonacci_sphere(n).T, axis=0))
        small = trimesh.convex.convex_hull(hull.vertices[support])
        offsets = np.einsum("ij,ij->i", small.face_normals, small.vertices[small.faces[:, 0]])
        is_out = (hull.vertices @ small.face_normals.T - offsets).max(axis=1) > 0.0
        outside = 0.0
        if is_out.any():
            outside = _max_distance_to_surface(small, hull.vertices[is_out])
        if outside <= tolerance or n >= max_directions:
            return small, outside
        n *= 2


def _max_distance_to_surface(mesh: trimesh.Trimesh, points: np.ndarray) -> float:
    """Largest over points of the exact distance to the mesh surface (all point-triangle pairs)."""
    tris = np.repeat(mesh.triangles[None], len(points), axis=0).reshape(-1, 3, 3)
    pts = np.repeat(points, len(mesh.faces), axis=0)
    closest = trimesh.triangles.closest_point(tris, pts)
    dist = np.linalg.norm(closest - pts, axis=1).reshape(len(points), len(mesh.faces))
    return float(dist.min(axis=1).max())
