"""The grasp search over many frames at once, against oracles that share no code with it: force closure by non-negative
least squares over a friction pyramid of its own, collision by python-fcl, inside-ness by the winding number, candidates
by brute force; and the batching itself: each frame gets what it gets alone, each IK group what it gets alone."""
from __future__ import annotations

import fcl
import numpy as np
import pytest
from scipy.optimize import nnls
from scipy.spatial import cKDTree
from test_grasp_list import SMALL, _crossings, _fcl_mesh, _fcl_shape, recheck

from planner.collision.object_screens import surface_cover
from planner.grasping.finger_workspace import hand_workspaces
from planner.grasping.grasp_list import compute_grasp_list, grasp_centre, grasp_frames, search_object
from planner.grasping.quality import contact_wrenches, hull_epsilon, separated
from planner.grasping.search import GraspSearch
from planner.model.hand_model import load_hand_model
from planner.model.shapes import generate

PYRAMID_EDGES = 32


def _tangents(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents of a unit normal, from the coordinate axis least aligned with it."""
    axis = np.eye(3)[np.argmin(np.abs(n))]
    t1 = axis - (axis @ n) * n
    t1 /= np.linalg.norm(t1)
    return t1, np.cross(n, t1)


def _positively_spans(W: np.ndarray) -> bool:
    """Whether the rows of W (m, 6) positively span R^6: each vector of the positive basis {e_1..e_6, -sum e_i} is a
    non-negative combination of them (NNLS residual ~ 0)."""
    basis = np.vstack([np.eye(6), -np.ones((1, 6))])
    return all(nnls(W.T, b)[1] < 1e-7 for b in basis)


def closed_with_cone(points, normals, com, mu, scale) -> bool:
    """Force closure with each contact's cone replaced by a 32-edge pyramid around it (edges at mu / cos(pi/32)): closure
    with any pyramid inside the cone (the planner's 8 edges) implies closure with this one."""
    wide = mu / np.cos(np.pi / PYRAMID_EDGES)
    rows = []
    for p, n in zip(points, normals):
        n = n / np.linalg.norm(n)
        t1, t2 = _tangents(n)
        for a in 2 * np.pi * np.arange(PYRAMID_EDGES) / PYRAMID_EDGES:
            f = -n + wide * (np.cos(a) * t1 + np.sin(a) * t2)
            rows.append(np.r_[f, np.cross(p - com, f) / scale])
    return _positively_spans(np.array(rows))


def _assert_closed(result) -> None:
    for r in range(len(result)):
        mask = result.contact_mask[r]
        assert closed_with_cone(result.contact_point[r][mask], result.contact_normal[r][mask], np.asarray(result.object_com),
                                result.mu, result.torque_scale), f"grasp {r} is not force-closed"


@pytest.fixture(scope="module")
def mug():
    return generate("mug", {})


@pytest.mark.parametrize("hand", ["right", "left"])
def test_every_grasp_on_the_statuette_is_force_closed_and_clear(default_scene, hand):
    spec = default_scene.robot.spec.arm(hand).hand
    result = compute_grasp_list(spec, hand, default_scene.object_mesh, SMALL, seed=5, workers=2)
    assert len(result) > 0
    _assert_closed(result)
    recheck(result, spec, default_scene.object_mesh, SMALL.ik_tolerance)


def test_every_grasp_on_a_generated_mug_is_force_closed_and_clear(default_scene, mug):
    spec = default_scene.robot.spec.arm("left").hand
    result = compute_grasp_list(spec, "left", mug, SMALL, seed=2, workers=2)
    assert len(result) > 0
    _assert_closed(result)
    recheck(result, spec, mug, SMALL.ik_tolerance)


@pytest.fixture(scope="module")
def search_and_frames(default_scene):
    hand = load_hand_model(default_scene.robot.spec.arm("right").hand)
    mesh = default_scene.object_mesh
    obj = search_object(mesh, [f.tip_radius for f in hand.fingers], SMALL)
    workspaces = hand_workspaces(hand, SMALL.workspace())
    search = GraspSearch(hand, workspaces, obj, mesh, SMALL.search(), SMALL.limit_margin)
    return search, grasp_frames(mesh, grasp_centre(workspaces), SMALL, 3)


def test_each_frame_gets_in_a_batch_what_it_gets_alone(search_and_frames):
    search, H = search_and_frames
    together = search.grasps(H)
    closed = [k for k, g in enumerate(together) if g.outcome == "closed"]
    assert closed and len({g.outcome for g in together}) >= 5
    picked = sorted(set(closed[:6]) | set(range(0, len(H), 37)))
    for k in picked:
        alone = search.grasps(H[k:k + 1])[0]
        assert alone.outcome == together[k].outcome, k
        if alone.outcome == "closed":
            assert np.array_equal(alone.finger_q, together[k].finger_q)
            assert np.array_equal(alone.contact_index, together[k].contact_index)
            assert alone.epsilon == together[k].epsilon


def test_ik_groups_stop_as_if_solved_alone(default_scene):
    finger = load_hand_model(default_scene.robot.spec.arm("left").hand).fingers[1]
    rng = np.random.default_rng(0)
    lower, upper = finger.reduced_limits(0.1)
    targets = finger.tip_positions(rng.uniform(lower, upper, (40, finger.dof)))
    q0 = rng.uniform(lower, upper, (40, finger.dof))
    groups = rng.integers(0, 5, 40)
    q, err, J = finger.ik(targets, q0, lower, upper, 2e-4, 4, groups=groups)
    for g in range(5):
        rows = groups == g
        q_alone, err_alone, J_alone = finger.ik(targets[rows], q0[rows], lower, upper, 2e-4, 4)
        assert np.array_equal(q[rows], q_alone) and np.array_equal(err[rows], err_alone) and np.array_equal(J[rows], J_alone)


def test_candidates_are_the_targets_in_the_finger_spheres_in_kd_tree_order(search_and_frames):
    search, H = search_and_frames
    fi = search.hand.thumb_first[0]
    ws, targets, found = search.workspaces[fi], search.targets[fi], search.finders[fi](H[:60])
    tree_order = list(search.obj.tree.indices)
    for k in range(60):
        local = (targets - H[k, :3, 3]) @ H[k, :3, :3]
        inside = np.linalg.norm(local[:, None] - ws.centres[None], axis=2) <= ws.radii
        expected = sorted(np.flatnonzero(inside.any(axis=1)), key=tree_order.index)
        mine = found.frame == k
        assert list(found.point[mine]) == expected
        assert np.array_equal(found.sphere[mine], np.argmax(inside[expected], axis=1))


def test_rejected_frames_could_not_give_a_grasp(search_and_frames, default_scene):
    from planner.grasping.reject import rejected

    search, H = search_and_frames
    reason, found = rejected(search, H)
    assert {"palm_inside", "body_collides", "thumb_misses"} <= set(reason)
    mesh, palm = default_scene.object_mesh, search.hand.body[0]
    for k in np.flatnonzero(reason == "palm_inside")[:20]:
        T = H[k] @ palm.placement
        centre = T[:3, :3] @ np.asarray(palm.geometry.aabb_center) + T[:3, 3]
        assert _crossings(centre, np.array([0.36, 0.48, 0.8]), mesh.triangles) % 2 == 1, k
    obj = _fcl_mesh(mesh)
    for k in np.flatnonzero(reason == "body_collides")[:40]:
        T = H[k] @ palm.placement
        shape = fcl.CollisionObject(_fcl_shape(palm.geometry, 0.0), fcl.Transform(T[:3, :3], T[:3, 3]))
        assert fcl.collide(shape, obj, fcl.CollisionRequest(), fcl.CollisionResult()) > 0, k
    thumb = search.hand.thumb_first[0]
    ws = search.workspaces[thumb]
    for k in np.flatnonzero(reason == "thumb_misses")[:40]:
        local = (search.targets[thumb] - H[k, :3, 3]) @ H[k, :3, :3]
        assert not (np.linalg.norm(local[:, None] - ws.centres[None], axis=2) <= ws.radii).any(), k
    for k in np.flatnonzero(reason == "unreachable"):
        assert sum(np.any(c.frame == k) for c in found) < 3


def test_screened_hits_are_hits_by_fcl(search_and_frames, default_scene):
    """Finger poses near the object: every one the point-set screen calls a hit, fcl finds hitting the mesh."""
    search, H = search_and_frames
    finger_index = search.hand.thumb_first[1]
    finger = search.hand.fingers[finger_index]
    rng = np.random.default_rng(1)
    frames = H[rng.integers(0, len(H), 400)]
    world = frames[:, None] @ finger.shape_poses(rng.uniform(finger.lower, finger.upper, (400, finger.dof)))
    sure = search.screen.hits(world, search.inside[finger_index][False])
    assert sure.sum() > 10
    obj = _fcl_mesh(default_scene.object_mesh)
    for k in np.flatnonzero(sure):
        hits = [fcl.collide(fcl.CollisionObject(_fcl_shape(s.geometry, 0.0), fcl.Transform(T[:3, :3], T[:3, 3])), obj,
                            fcl.CollisionRequest(), fcl.CollisionResult()) > 0 for s, T in zip(finger.shapes, world[k])]
        assert any(hits), k


def test_screened_clear_shapes_miss_by_fcl(search_and_frames, default_scene):
    """Finger poses near the object: every shape the screen calls clear, its bounding sphere included, fcl finds apart
    from the mesh; and the screen calls many clear."""
    search, H = search_and_frames
    finger_index = search.hand.thumb_first[2]
    finger = search.hand.fingers[finger_index]
    rng = np.random.default_rng(2)
    world = H[rng.integers(0, len(H), 300)][:, None] @ finger.shape_poses(rng.uniform(finger.lower, finger.upper, (300, finger.dof)))
    centres = np.array([[T[:3, :3] @ np.asarray(s.geometry.aabb_center) + T[:3, 3] for s, T in zip(finger.shapes, w)] for w in world])
    radii = np.array([s.geometry.aabb_radius for s in finger.shapes])
    clear = search.screen.clear(centres, radii)
    assert 0.2 < clear.mean() < 0.9
    obj = _fcl_mesh(default_scene.object_mesh)
    for k, j in zip(*np.nonzero(clear)):
        T, ball = world[k, j], fcl.CollisionObject(fcl.Sphere(radii[j]), fcl.Transform(centres[k, j]))
        shape = fcl.CollisionObject(_fcl_shape(finger.shapes[j].geometry, 0.0), fcl.Transform(T[:3, :3], T[:3, 3]))
        assert fcl.distance(ball, obj, fcl.DistanceRequest(), fcl.DistanceResult()) > 0, (k, j)
        assert fcl.collide(shape, obj, fcl.CollisionRequest(), fcl.CollisionResult()) == 0, (k, j)


def test_every_surface_point_lies_near_the_cover(default_scene):
    mesh = default_scene.object_mesh
    points, within = surface_cover(np.asarray(mesh.triangles), 0.004)
    assert within <= 0.004 and len(points) < 20 * mesh.area / 0.004**2
    samples = np.random.default_rng(3).random((4000, 2))
    folded = samples.sum(axis=1) > 1
    samples[folded] = 1 - samples[folded]  # uniform on each triangle
    faces = np.random.default_rng(4).integers(0, len(mesh.faces), 4000)
    v = mesh.vertices[mesh.faces[faces]]
    surface = v[:, 0] + samples[:, :1] * (v[:, 1] - v[:, 0]) + samples[:, 1:] * (v[:, 2] - v[:, 0])
    assert cKDTree(points).query(surface)[0].max() <= within + 1e-12
    tri = np.asarray(mesh.triangles)
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    for p in points[:: max(1, len(points) // 300)]:  # each cover point lies in a triangle: on its plane, inside its edges
        plane = np.abs(np.einsum("fi,fi->f", p - tri[:, 0], normals)) <= 1e-12 * np.linalg.norm(normals, axis=1)
        inside = np.all([np.einsum("fi,fi->f", np.cross(tri[:, (i + 1) % 3] - tri[:, i], p - tri[:, i]), normals) >= -1e-18
                         for i in range(3)], axis=0)
        assert np.any(plane & inside), p


def test_separated_wrench_sets_are_not_force_closed():
    rng = np.random.default_rng(4)
    sets = []
    for _ in range(300):
        c = rng.integers(3, 5)
        normals = rng.normal(size=(c, 3))
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        points = 0.05 * normals + rng.normal(0, 0.01, (c, 3))
        sets.append(contact_wrenches(points, normals, np.zeros(3), 0.5, 8, 0.06))
    apart = separated(sets)
    assert 30 < apart.sum() < len(sets)  # both kinds occur
    for w, a in zip(sets, apart):
        if a:
            assert hull_epsilon(w) <= 1e-9 and not _positively_spans(w)
