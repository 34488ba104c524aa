"""The grasp planner's models: hand kinematics and IK, finger workspace spheres, object point set, grasp frames."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
import trimesh
from sandbox import forbid

from planner.grasping.finger_workspace import WorkspaceParams, finger_workspace, hand_workspaces, sphere_hierarchy
from planner.grasping.frames import box_grid, hopf_rotations
from planner.grasping.object_model import build_object_model, object_model, vertex_mean_curvature
from planner.model.hand_model import load_hand_model
from planner.model.robot import _load
from planner.model.robot_spec import load_robot_spec


@pytest.fixture(scope="module")
def hand_spec():
    return load_robot_spec("alex_allegro.toml").arm("right").hand


@pytest.fixture(scope="module")
def hand(hand_spec):
    return load_hand_model(hand_spec)


def test_finger_kinematics_match_pinocchio(hand_spec, hand):
    model, _, _ = _load(hand_spec.urdf.read_text(), hand_spec.urdf)
    data = model.createData()
    rng = np.random.default_rng(0)
    for spec_finger, finger in zip(hand_spec.fingers, hand.fingers):
        q = rng.uniform(finger.lower, finger.upper, (4, finger.dof))
        tips, J = finger.jacobians(q)
        for qi, tip in zip(q, tips):
            full = pin.neutral(model)
            for name, value in zip(finger.joints, qi):
                full[model.joints[model.getJointId(name)].idx_q] = value
            pin.framesForwardKinematics(model, data, full)
            assert np.allclose(data.oMf[model.getFrameId(spec_finger.tip_frame)].translation, tip, atol=1e-12)
        h = 1e-7
        numeric = np.stack([(finger.tip_positions(q + h * np.eye(finger.dof)[j]) - tips) / h for j in range(finger.dof)], -1)
        assert np.allclose(J, numeric, atol=1e-5)


def test_thumb_is_planned_first_and_the_palm_is_the_hand_body(hand):
    assert hand.finger_names[hand.thumb_first[0]] == "thumb"
    assert len(hand.body) >= 1 and all(s.link == -1 for s in hand.body)
    assert all(sum(s.is_tip for s in f.shapes) == 1 for f in hand.fingers)


def test_finger_ik_puts_the_fingertip_where_asked(hand):
    rng = np.random.default_rng(1)
    for finger, ws in zip(hand.fingers, hand_workspaces(hand)):
        lower, upper = finger.reduced_limits(0.1)
        goal_q = rng.uniform(lower, upper, (300, finger.dof))
        targets = finger.tip_positions(goal_q)
        _, seed = ws.seeds().query(targets)
        q, err, J = finger.ik(targets, ws.seed_q[seed], lower, upper, tolerance=1e-6, iterations=30)
        assert np.all((q >= lower - 1e-12) & (q <= upper + 1e-12))
        tips, jacobians = finger.jacobians(q)
        assert np.array_equal(np.linalg.norm(tips - targets, axis=1), err) and np.array_equal(jacobians, J)
        assert np.mean(err < 1e-4) > 0.95, finger.name  # local IK: the rest stop on a limit of the reduced range


def _inside_grid(ws, centre, radius):
    """Every grid point within the sphere is an occupied voxel of the workspace."""
    lo = np.floor((centre - radius - ws.origin) / ws.voxel).astype(int)
    hi = np.ceil((centre + radius - ws.origin) / ws.voxel).astype(int)
    cells = np.stack(np.meshgrid(*[np.arange(a, b + 1) for a, b in zip(lo, hi)], indexing="ij"), -1).reshape(-1, 3)
    cells = cells[np.linalg.norm(ws.origin + cells * ws.voxel - centre, axis=1) < radius]
    if np.any(cells < 0) or np.any(cells >= ws.occupied.shape):
        return False
    return bool(np.all(ws.occupied[tuple(cells.T)]))


def test_sphere_hierarchy_properties(hand):
    p = WorkspaceParams()
    for finger in hand.fingers:
        ws = finger_workspace(finger, p)
        assert 1 <= len(ws.radii) <= p.max_spheres
        assert np.all(np.diff(ws.radii) <= 1e-12)  # largest first
        assert np.all(ws.radii >= p.min_radius)
        assert all(_inside_grid(ws, c, r) for c, r in zip(ws.centres, ws.radii))
        assert ws.boundary.sum() > 0 and np.all(ws.occupied[ws.boundary])


def test_sphere_hierarchy_stop_rules():
    # a 30 x 10 x 10 cm box sampled every centimetre: the first sphere sits in the middle, 5 cm from the boundary
    axes = [np.arange(0, 31), np.arange(0, 11), np.arange(0, 11)]
    cells = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    on_face = np.any((cells == 0) | (cells == [30, 10, 10]), axis=1)
    inner, boundary = cells[~on_face] * 0.01, cells[on_face] * 0.01
    centres, radii = sphere_hierarchy(inner, boundary, max_spheres=100, min_radius=0.02)
    assert radii[0] == pytest.approx(0.05) and centres[0][1:] == pytest.approx([0.05, 0.05])
    assert 1 < len(radii) < 100 and radii.min() >= 0.02 and np.all(np.diff(radii) <= 1e-12)
    c3, r3 = sphere_hierarchy(inner, boundary, max_spheres=3, min_radius=0.0)
    assert len(r3) == 3 and np.allclose(r3, radii[:3]) and np.allclose(c3, centres[:3])
    for i in range(len(radii)):  # each centre lies outside every earlier sphere
        assert np.all(np.linalg.norm(centres[:i] - centres[i], axis=1) > radii[:i])
    none, _ = sphere_hierarchy(inner, boundary, max_spheres=10, min_radius=0.06)
    assert len(none) == 0


def test_workspaces_are_cached_per_hand(hand, monkeypatch):
    first = hand_workspaces(hand)
    forbid(monkeypatch, "planner.grasping.finger_workspace.finger_workspace")
    again = hand_workspaces(hand)
    for a, b in zip(first, again):
        assert np.array_equal(a.centres, b.centres) and np.array_equal(a.occupied, b.occupied)


def test_object_point_set_is_even_on_the_surface_with_outward_normals():
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=0.05)
    model = build_object_model(sphere, 0.006)
    dist = np.linalg.norm(model.points, axis=1)
    assert np.allclose(dist, 0.05, atol=1e-3)
    assert np.all(np.einsum("ij,ij->i", model.points / dist[:, None], model.normals) > 0.99)
    nearest, _ = model.tree.query(model.points, 2)
    assert nearest[:, 1].min() >= 0.006
    assert np.allclose(model.curvature, 20.0, rtol=0.1)  # mean curvature 1/R
    assert model.radius == pytest.approx(0.05, rel=1e-3)
    leaves = model.leaf_ids()
    assert leaves.min() == 0 and len(np.unique(leaves)) == leaves.max() + 1 > 1


def test_mean_curvature_is_signed():
    box = trimesh.creation.box(extents=[0.1, 0.1, 0.1])
    assert np.all(vertex_mean_curvature(box) > 0)  # convex corners


def test_object_models_are_cached_per_mesh_and_step(monkeypatch):
    box = trimesh.creation.box(extents=[0.1, 0.1, 0.1])
    built = object_model(box, 0.01)
    forbid(monkeypatch, "planner.grasping.object_model.build_object_model")
    assert np.array_equal(built.points, object_model(box, 0.01).points)


def test_orientations_are_rotations_spread_evenly():
    R = hopf_rotations(512)
    assert np.allclose(R @ R.transpose(0, 2, 1), np.eye(3), atol=1e-12) and np.allclose(np.linalg.det(R), 1)
    assert np.allclose(hopf_rotations(100), R[:100])  # incremental: a prefix of a longer sequence
    z = R[:, :, 2]
    assert np.linalg.norm(z.mean(0)) < 0.05  # the fingers' axis covers the sphere evenly
    angles = np.arccos(np.clip((np.trace(R[:64, None].transpose(0, 1, 3, 2) @ R[None, :64], axis1=2, axis2=3) - 1) / 2, -1, 1))
    np.fill_diagonal(angles, np.inf)
    assert angles.min() > 0.15  # no two of the first 64 orientations nearly coincide


def test_position_grid_fills_the_box():
    lower, upper = np.array([0.0, 0.0, 0.0]), np.array([0.2, 0.1, 0.3])
    pts = box_grid(lower, upper, 100)
    assert 50 <= len(pts) <= 200
    assert np.all(pts > lower) and np.all(pts < upper)
