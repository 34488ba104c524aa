"""Force closure and the Ferrari–Canny epsilon on analytic contact and wrench sets."""
from __future__ import annotations

import itertools

import numpy as np
import pytest

from planner.grasping.quality import contact_wrenches, curvature_score, ellipsoid_alignment, force_closure, hull_epsilon, tangent_bases


def _equator(angles_deg, radius=0.05):
    a = np.deg2rad(angles_deg)
    points = radius * np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], axis=1)
    return points, points / radius


def test_three_frictional_contacts_120_degrees_apart_are_force_closed():
    points, normals = _equator([0, 120, 240])
    closed, eps = force_closure(points, normals, np.zeros(3), mu=0.5, edges=8, torque_scale=0.05)
    assert closed and eps > 0


def test_two_antipodal_contacts_are_not_force_closed():
    points, normals = _equator([0, 180])
    assert force_closure(points, normals, np.zeros(3), mu=0.0, edges=8, torque_scale=0.05) == (False, 0.0)
    # with friction, still no resistance to torques about the line through the two contacts
    assert not force_closure(points, normals, np.zeros(3), mu=0.5, edges=8, torque_scale=0.05)[0]


def test_contacts_on_one_side_are_not_force_closed():
    points, normals = _equator([0, 20, 40])
    assert not force_closure(points, normals, np.zeros(3), mu=0.5, edges=8, torque_scale=0.05)[0]


def test_epsilon_of_the_cross_polytope_is_one_over_root_six():
    # the hull of +-e_i in R^6: every facet is sum(|x_i|) = 1 at distance 1/sqrt(6) from the origin
    wrenches = np.concatenate([np.eye(6), -np.eye(6)])
    assert hull_epsilon(wrenches) == pytest.approx(1 / np.sqrt(6), rel=1e-6)


def test_epsilon_of_the_hypercube_is_one():
    wrenches = np.array(list(itertools.product([-1.0, 1.0], repeat=6)))
    assert hull_epsilon(wrenches) == pytest.approx(1.0, rel=1e-6)


def test_epsilon_of_a_hull_missing_the_origin_is_not_positive():
    wrenches = np.concatenate([np.eye(6), -np.eye(6)]) + [2.0, 0, 0, 0, 0, 0]
    assert hull_epsilon(wrenches) <= 0
    assert hull_epsilon(np.eye(6)) == 0.0  # too few points for a 6-D hull


def test_epsilon_is_invariant_under_rotating_the_grasp_and_scales_with_the_force():
    points, normals = _equator([0, 120, 240])
    eps = force_closure(points, normals, np.zeros(3), 0.5, 8, 0.05)[1]
    c, s = np.cos(0.7), np.sin(0.7)
    R = np.array([[1, 0, 0], [0, c, -s], [0, s, c]]) @ np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    # the cone edges turn about each normal with the tangent basis: the linearisation moves epsilon slightly
    assert force_closure(points @ R.T, normals @ R.T, np.zeros(3), 0.5, 8, 0.05)[1] == pytest.approx(eps, rel=1e-2)
    shifted = force_closure(points + [0.1, 0, 0], normals, np.array([0.1, 0, 0]), 0.5, 8, 0.05)[1]
    assert shifted == pytest.approx(eps, rel=1e-6)
    assert force_closure(points, normals, np.zeros(3), 0.8, 8, 0.05)[1] > eps  # more friction, more margin


def test_epsilon_is_the_smallest_support_value_over_directions():
    # independent: eps = min over unit u of max_i w_i . u (support function); random directions bound it from above
    points, normals = _equator([0, 120, 240])
    W = contact_wrenches(points, normals, np.zeros(3), 0.5, 8, 0.05)
    eps = hull_epsilon(W)
    u = np.random.default_rng(0).normal(size=(200_000, 6))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    bound = np.min(np.max(u @ W.T, axis=1))
    assert eps <= bound + 1e-9 and bound < 1.3 * eps


def test_cone_edges_have_unit_normal_component_and_friction_ratio_mu():
    points, normals = _equator([0, 120, 240])
    W = contact_wrenches(points, normals, np.zeros(3), 0.5, 8, 0.05).reshape(3, 8, 6)
    forces = W[:, :, :3]
    inward = -np.einsum("cej,cj->ce", forces, normals)
    assert np.allclose(inward, 1.0)
    tangential = np.linalg.norm(forces + inward[..., None] * normals[:, None, :], axis=2)
    assert np.allclose(tangential, 0.5)
    t1, t2 = tangent_bases(normals)
    assert np.allclose(np.einsum("ij,ij->i", t1, normals), 0) and np.allclose(np.einsum("ij,ij->i", t1, t2), 0)


def test_ellipsoid_and_curvature_scores():
    J = np.diag([1.0, 2.0, 3.0])  # J J^T smallest eigenvalue along x: the force ellipsoid's major axis
    assert ellipsoid_alignment(J, np.array([1.0, 0, 0])) == pytest.approx(1.0)
    assert ellipsoid_alignment(J, np.array([0, 0, 1.0])) == pytest.approx(0.0, abs=1e-12)
    assert curvature_score(np.array([0.0]), 0.01) == 1.0
    assert curvature_score(np.array([100.0]), 0.01) == pytest.approx(0.5)
