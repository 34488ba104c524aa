"""Conversions from pinocchio/coal geometry to what viser draws: triangle meshes and wxyz poses."""
from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
import trimesh
from scipy.spatial.transform import Rotation


def coal_to_trimesh(geometry: coal.CollisionGeometry, scale: np.ndarray | None = None, grow: float = 0.0) -> trimesh.Trimesh:
    """A triangle mesh, in the geometry's own frame, of a coal BVH mesh, convex or primitive, grown by `grow` (m)."""
    if isinstance(geometry, coal.BVHModelBase):
        vertices = np.asarray(geometry.vertices()) * (1.0 if scale is None else np.asarray(scale))
        faces = np.array([[t[0], t[1], t[2]] for t in map(geometry.tri_indices, range(geometry.num_tris))], dtype=np.int64)
        mesh = trimesh.Trimesh(vertices, faces, process=False)
        return trimesh.Trimesh(vertices + grow * mesh.vertex_normals, faces, process=False) if grow > 0 else mesh
    if isinstance(geometry, coal.Convex):
        hull = trimesh.convex.convex_hull(np.asarray(geometry.points()))
        return trimesh.convex.convex_hull(hull.vertices + grow * hull.vertex_normals) if grow > 0 else hull
    if isinstance(geometry, coal.Box):
        return trimesh.creation.box(extents=2.0 * (np.asarray(geometry.halfSide) + grow))
    if isinstance(geometry, coal.Sphere):
        return trimesh.creation.icosphere(subdivisions=2, radius=geometry.radius + grow)
    if isinstance(geometry, coal.Cylinder):
        return trimesh.creation.cylinder(radius=geometry.radius + grow, height=2.0 * (geometry.halfLength + grow), sections=32)
    if isinstance(geometry, coal.Capsule):
        return trimesh.creation.capsule(radius=geometry.radius + grow, height=2.0 * geometry.halfLength, count=[16, 16])
    raise TypeError(f"cannot draw a {type(geometry).__name__}")


def poses_wxyz(placements: list[pin.SE3]) -> tuple[np.ndarray, np.ndarray]:
    """(n, 4) wxyz quaternions and (n, 3) positions of a list of SE3 placements."""
    if not placements:
        return np.zeros((0, 4)), np.zeros((0, 3))
    rotations = np.stack([M.rotation for M in placements])
    xyzw = Rotation.from_matrix(rotations).as_quat()
    return xyzw[:, [3, 0, 1, 2]], np.stack([M.translation for M in placements])


def matrix_wxyz(T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """wxyz quaternion and position of a 4x4 homogeneous transform."""
    x, y, z, w = Rotation.from_matrix(T[:3, :3]).as_quat()
    return np.array([w, x, y, z]), np.asarray(T[:3, 3], float)
