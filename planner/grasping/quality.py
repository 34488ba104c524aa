"""Grasp stability and quality (paper IV-A.3): force closure, Ferrari–Canny epsilon, force ellipsoid and curvature scores.

Contacts are frictional points: the friction cone (coefficient mu) is linearised with k edges,
each a force of unit normal component pushing into the object. A wrench is (force, torque / L),
torques taken about the centre of mass and divided by the characteristic length L (the object's
largest radius from its centre of mass), so both halves are in newtons. The grasp is
force-closed when the origin lies strictly inside the convex hull of the edge wrenches (the
grasp wrench space, L1 / Ferrari–Canny), and epsilon is the distance from the origin to the
nearest hull facet: the largest ball about the origin inside the hull.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, QhullError

CLOSURE_TOLERANCE = 1e-9
SEPARATION = 1e-6  # N: how far beyond the origin's side a certificate of `separated` puts every wrench (far above qhull's joggle)
SEPARATION_ITERATIONS = 256


def tangent_bases(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents (..., 3) orthogonal to each unit normal (..., 3) and to each other."""
    helper = np.where(np.abs(normals[..., :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    t1 = np.cross(normals, helper)
    t1 /= np.linalg.norm(t1, axis=-1, keepdims=True)
    return t1, np.cross(normals, t1)


def contact_wrenches(points: np.ndarray, normals: np.ndarray, com: np.ndarray, mu: float, edges: int,
                     torque_scale: float) -> np.ndarray:
    """(..., c * edges, 6) wrenches of the friction-cone edges at contacts (..., c, 3) with outward normals (leading
    axes: many grasps of c contacts at once, each the same as alone)."""
    normals = normals / np.linalg.norm(normals, axis=-1, keepdims=True)
    t1, t2 = tangent_bases(normals)
    a = 2.0 * np.pi * np.arange(edges) / edges
    forces = -normals[..., None, :] + mu * (np.cos(a)[:, None] * t1[..., None, :] + np.sin(a)[:, None] * t2[..., None, :])
    torques = np.cross((points - com)[..., None, :], forces) / torque_scale
    return np.concatenate([forces, torques], axis=-1).reshape(*points.shape[:-2], -1, 6)


def hull_epsilon(wrenches: np.ndarray) -> float:
    """Signed distance from the origin to the boundary of the wrenches' convex hull (<= 0 when not strictly inside)."""
    if len(wrenches) <= 6 or np.linalg.matrix_rank(wrenches, tol=1e-9) < 6:
        return 0.0
    try:
        hull = ConvexHull(wrenches, qhull_options="QJ")  # joggled: simplicial facets, twice as fast, deterministic
    except QhullError:
        return 0.0
    return float(np.min(-hull.equations[:, -1]))


def wrench_closure(wrenches: np.ndarray) -> tuple[bool, float]:
    """Whether cone-edge wrenches are force-closed, and the Ferrari–Canny epsilon (0 when not)."""
    eps = hull_epsilon(wrenches)
    return eps > CLOSURE_TOLERANCE, max(eps, 0.0)


def force_closure(points: np.ndarray, normals: np.ndarray, com: np.ndarray, mu: float, edges: int,
                  torque_scale: float) -> tuple[bool, float]:
    """Whether the contacts are force-closed, and the Ferrari–Canny epsilon (0 when not)."""
    return wrench_closure(contact_wrenches(points, normals, com, mu, edges, torque_scale))


def separated(wrench_sets: list[np.ndarray], iterations: int = SEPARATION_ITERATIONS) -> np.ndarray:
    """Per set of wrenches, True when a hyperplane through the origin leaves every wrench at least `SEPARATION` on one
    side, so the origin is outside their hull and the grasp cannot be force-closed; False: not shown (the hull decides).

    Gilbert's nearest-point iteration runs on all sets at once (shorter sets padded with their first wrench, which
    leaves a hull unchanged): a hull point x whose support value min_i x.w_i is positive is the certificate. It costs a
    fraction of a 6-D hull, and most grasps with three or more contacts are not force-closed."""
    if not wrench_sets:
        return np.zeros(0, bool)
    m = max(len(w) for w in wrench_sets)
    W = np.stack([np.concatenate([w, np.repeat(w[:1], m - len(w), axis=0)]) for w in wrench_sets])
    rows = np.arange(len(W))
    x = W.mean(axis=1)
    apart = np.zeros(len(W), bool)
    for _ in range(iterations):
        support = np.einsum("bmi,bi->bm", W, x)
        apart |= support.min(axis=1) > SEPARATION * np.linalg.norm(x, axis=1)
        diff = x - W[rows, np.argmin(support, axis=1)]
        step = np.clip(np.einsum("bi,bi->b", x, diff) / np.maximum(np.einsum("bi,bi->b", diff, diff), 1e-300), 0.0, 1.0)
        x = x - step[:, None] * diff
    return apart


def ellipsoid_alignment(jacobian: np.ndarray, normal: np.ndarray) -> float:
    """|cos| of the angle between a contact normal and the major axis of the finger's force ellipsoid at J (3 x k).

    Fingertip forces f that joint torques of unit norm produce satisfy f^T (J J^T) f <= 1, so the
    force ellipsoid's major axis is the eigenvector of J J^T with the smallest eigenvalue.
    """
    _, vectors = np.linalg.eigh(jacobian @ jacobian.T)
    return float(abs(vectors[:, 0] @ normal) / np.linalg.norm(normal))


def curvature_score(curvatures: np.ndarray, tip_radius: float) -> float:
    """Mean over contacts of 1 / (1 + |H| r): 1 on flat surface, 1/2 where the surface is as curved as the fingertip."""
    return float(np.mean(1.0 / (1.0 + np.abs(curvatures) * tip_radius)))


def com_score(points: np.ndarray, com: np.ndarray, torque_scale: float) -> tuple[float, float]:
    """The distance from the contacts' centroid to the centre of mass, and its score 1 - d / L (clipped at 0)."""
    d = float(np.linalg.norm(points.mean(0) - com))
    return d, max(0.0, 1.0 - d / torque_scale)
