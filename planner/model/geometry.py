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
