"""coal shapes from what the models hold (trimesh meshes, primitives, URDF geometries), and back to triangle meshes.

The models keep meshes and primitive sizes; they ask here for the coal geometry that checks them. Meshes of
URDF links are replaced by their convex hulls, which contain them. The workbench draws coal shapes through
`to_trimesh`.
"""
from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
import trimesh

Geometry = coal.CollisionGeometry
"""A collision shape in its own frame (what a model holds without naming coal)."""


def transform3s(T: np.ndarray) -> coal.Transform3s:
    """coal's transform of a 4x4 homogeneous pose."""
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


def is_mesh(geometry: Geometry) -> bool:
    """True for a triangle mesh (a BVH model), false for a convex or a primitive."""
    return isinstance(geometry, coal.BVHModelBase)


def is_sphere(geometry: Geometry) -> bool:
    return isinstance(geometry, coal.Sphere)


def sphere(radius: float) -> Geometry:
    return coal.Sphere(radius)


def convex_geometry(obj: pin.GeometryObject) -> Geometry:
    """A URDF geometry's shape with a mesh replaced by its (scaled) convex hull; a primitive as it is."""
    if is_mesh(obj.geometry):
        vertices = np.asarray(obj.geometry.vertices()) * np.asarray(obj.meshScale)
        return coal_convex(trimesh.convex.convex_hull(vertices))
    return obj.geometry


def primitive(shape: str, size: tuple[float, ...], mesh: trimesh.Trimesh | None = None) -> Geometry:
    """The exact coal shape of an obstacle in its own frame. shape: box (size x, y, z), cylinder or capsule (radius,
    length), sphere (radius,), else the triangle mesh `mesh`."""
    if shape == "box":
        return coal.Box(*size)
    if shape == "cylinder":
        return coal.Cylinder(size[0], size[1])
    if shape == "capsule":
        return coal.Capsule(size[0], size[1])
    if shape == "sphere":
        return coal.Sphere(size[0])
    return coal_mesh(mesh)


def to_trimesh(geometry: Geometry, scale: np.ndarray | None = None, grow: float = 0.0) -> trimesh.Trimesh:
    """A triangle mesh, in the geometry's own frame, of a coal BVH mesh, convex or primitive, grown by `grow` (m)."""
    if is_mesh(geometry):
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
