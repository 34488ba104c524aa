"""How deep points lie inside a closed triangle mesh, for the test oracle: numpy only, no planner code.

The signed distance of a point is its distance to the nearest triangle, positive inside the mesh. Inside is told by
the nearest triangle's outward normal when the nearest point lies within that triangle, else (nearest on an edge or a
corner, where the normals disagree) by the generalized winding number: the triangles' solid angles at the point over
4π, one half or more inside. Only the triangles near the points are measured: a bound from the mesh's vertices rules
the others out.
"""
from __future__ import annotations

import numpy as np
import trimesh

SPACING = 0.002  # m: the largest gap between a shape's surface points (a face pressed in is found at its depth)
CHUNK = 200_000  # point-triangle pairs per numpy pass (memory)


def surface_points(mesh: trimesh.Trimesh) -> np.ndarray:
    """Points on the surface of a closed shape, no two neighbours more than SPACING apart: its triangles subdivided."""
    vertices, _ = trimesh.remesh.subdivide_to_size(mesh.vertices, mesh.faces, SPACING)
    return np.asarray(vertices, float)


def _dot(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return np.einsum("...k,...k->...", x, y)


def _to_segments(p: np.ndarray, a: np.ndarray, ab: np.ndarray, ab2: np.ndarray) -> np.ndarray:
    """(n, m) distances of points p (n, 1, 3) to the segments from a along ab (m, 3), ab2 = |ab|²."""
    t = np.clip(_dot(p - a, ab) / ab2, 0.0, 1.0)
    return np.linalg.norm(p - (a + t[..., None] * ab), axis=2)


class ClosedMesh:
    """A watertight triangle mesh with what the signed distance of points needs precomputed per triangle."""

    def __init__(self, mesh: trimesh.Trimesh):
        tri = np.asarray(mesh.triangles, float)
        self.vertices = np.asarray(mesh.vertices, float)
        self.a, self.b, self.c = tri[:, 0], tri[:, 1], tri[:, 2]
        self.lo, self.hi = tri.min(axis=1), tri.max(axis=1)
        self.v0, self.v1 = self.b - self.a, self.c - self.a
        self.edges = [(self.a, self.v0), (self.b, self.c - self.b), (self.c, -self.v1)]
        self.edges = [(start, e, np.maximum(_dot(e, e), 1e-30)) for start, e in self.edges]
        self.d00, self.d01, self.d11 = _dot(self.v0, self.v0), _dot(self.v0, self.v1), _dot(self.v1, self.v1)
        self.denom = np.maximum(self.d00 * self.d11 - self.d01 ** 2, 1e-30)
        normal = np.cross(self.v0, self.v1)
        outward = np.sign(_dot(self.a, normal).sum())  # six times the enclosed volume: > 0 when the normals face out
        self.normal = outward * normal / np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-30)

    def _nearest(self, p: np.ndarray, near: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(distance, signed distance or nan where the nearest point is on an edge) of points p (n, 3) to the
        triangles `near` (indices)."""
        a, n = self.a[near], self.normal[near]
        w2 = p[:, None, :] - a
        d20, d21 = _dot(w2, self.v0[near]), _dot(w2, self.v1[near])
        d00, d01, d11, denom = self.d00[near], self.d01[near], self.d11[near], self.denom[near]
        v, w = (d11 * d20 - d01 * d21) / denom, (d00 * d21 - d01 * d20) / denom
        height = _dot(w2, n)
        face = np.where((v >= 0) & (w >= 0) & (v + w <= 1), np.abs(height), np.inf)
        edges = np.min([_to_segments(p[:, None, :], s[near], e[near], e2[near]) for s, e, e2 in self.edges], axis=0)
        k = np.argmin(np.minimum(face, edges), axis=1)
        rows = np.arange(len(p))
        distance = np.minimum(face, edges)[rows, k]
        on_face = face[rows, k] <= edges[rows, k]
        return distance, np.where(on_face, -np.sign(height[rows, k]) * distance, np.nan)

    def _inside(self, p: np.ndarray) -> np.ndarray:
        """Whether each point (n, 3) is inside: its generalized winding number is one half or more."""
        a, b, c = (x[None] - p[:, None] for x in (self.a, self.b, self.c))
        la, lb, lc = (np.linalg.norm(x, axis=2) for x in (a, b, c))
        den = la * lb * lc + _dot(a, b) * lc + _dot(a, c) * lb + _dot(b, c) * la
        return np.abs(np.arctan2(_dot(a, np.cross(b, c)), den).sum(axis=1)) / (2 * np.pi) >= 0.5

    def signed_distances(self, points: np.ndarray) -> np.ndarray:
        """(n,) signed distance of each point (n, 3) to the mesh: inside > 0."""
        bound = np.sqrt(((points[:, None] - self.vertices[None]) ** 2).sum(axis=2).min(axis=1)).max()
        near = np.flatnonzero(np.all((self.lo <= points.max(axis=0) + bound) & (self.hi >= points.min(axis=0) - bound), axis=1))
        step = max(1, CHUNK // len(near))
        out = np.empty(len(points))
        for s in range(0, len(points), step):
            p = points[s:s + step]
            distance, signed = self._nearest(p, near)
            edge = np.isnan(signed)
            if edge.any():
                signed[edge] = np.where(self._inside(p[edge]), 1.0, -1.0) * distance[edge]
            out[s:s + step] = signed
        return out
