"""The motion step end to end on the default task (the example session's earlier steps), re-checked independently.

The oracle shares no code with the planner's checker: the URDFs' own collision geometry (full link
meshes, not hulls; the fingers' boxes and spheres) through python-fcl, posed by forward kinematics.
Every trajectory sample and nine more configurations between consecutive samples (the samples of
one straight segment are collinear, corners are samples, so these lie on the planned path) are
checked: robot against the obstacles; robot against the object at the pose the result gives (the
holding hand, and the hand working at the object during its contact motions, excepted: they touch it
by design); the object while carried against the obstacles (its support excepted while it is lifted
or set down); and links of different parts (each arm with its hand, the torso) against each other,
except pairs the oracle itself finds touching at rest or joined by a joint.
"""
from __future__ import annotations

import shutil
from pathlib import Path

import fcl
import numpy as np
import pinocchio as pin
import pytest

from planner.runner import run_pipeline
from planner.session import Session

EXAMPLE = Path(__file__).resolve().parent.parent / "sessions" / "default-example"
pytestmark = pytest.mark.slow


def _planned(folder: Path) -> Session:
    shutil.copytree(EXAMPLE, folder)
    session = Session.open(folder)
    if "motion" in session.finished():
        session = session.branch(folder.parent / (folder.name + "-branch"), "motion")
    run_pipeline(session)
    return session


@pytest.fixture(scope="module")
def planned(tmp_path_factory):
    session = _planned(tmp_path_factory.mktemp("motion") / "a")
    return session, session.result("motion")


def _fcl_geometry(geom, scale) -> tuple[fcl.CollisionGeometry, np.ndarray | None]:
    """The URDF collision shape as an fcl shape (and its vertices for a mesh)."""
    if hasattr(geom, "vertices"):
        v = np.asarray(geom.vertices()) * np.asarray(scale)
        tris = np.array([[t[0], t[1], t[2]] for t in (geom.tri_indices(i) for i in range(geom.num_tris))], np.int32)
        m = fcl.BVHModel()
        m.beginModel(len(v), len(tris))
        m.addSubModel(v, tris)
        m.endModel()
        return m, v
    if hasattr(geom, "halfSide"):
        return fcl.Box(*(2 * np.asarray(geom.halfSide))), None
    if hasattr(geom, "halfLength"):
        return fcl.Cylinder(geom.radius, 2 * geom.halfLength), None
    return fcl.Sphere(geom.radius), None


def _mesh(mesh) -> fcl.BVHModel:
    m = fcl.BVHModel()
    m.beginModel(len(mesh.vertices), len(mesh.faces))
    m.addSubModel(np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int32))
    m.endModel()
    return m


def _fcl_geometry_of_obstacle(ob) -> tuple[fcl.CollisionGeometry, np.ndarray | None]:
    if ob.shape == "box":
        return fcl.Box(*ob.size), None
    if ob.shape == "sphere":
        return fcl.Sphere(ob.size[0]), None
    if ob.shape == "cylinder":
        return fcl.Cylinder(ob.size[0], ob.size[1]), None
    if ob.shape == "capsule":
        return fcl.Capsule(ob.size[0], ob.size[1]), None
    return _mesh(ob.mesh), np.asarray(ob.mesh.vertices, float)


def _tf(T: np.ndarray) -> fcl.Transform:
    return fcl.Transform(np.asarray(T[:3, :3]), np.asarray(T[:3, 3]))


def _radius(geom: fcl.CollisionGeometry, vertices: np.ndarray | None) -> tuple[np.ndarray, float]:
    """A bounding sphere (centre in the shape's frame, radius) of an fcl shape."""
    if vertices is not None:
        c = (vertices.min(axis=0) + vertices.max(axis=0)) / 2
        return c, float(np.linalg.norm(vertices - c, axis=1).max())
    if isinstance(geom, fcl.Box):
        return np.zeros(3), float(np.linalg.norm(geom.side) / 2)
    if isinstance(geom, (fcl.Cylinder, fcl.Capsule)):
        return np.zeros(3), float(np.hypot(geom.radius, geom.lz / 2) + (geom.radius if isinstance(geom, fcl.Capsule) else 0))
    return np.zeros(3), float(geom.radius)


class Oracle:
    """Independent collision checks of a robot configuration with the object at a pose (see the module docstring).

    Bounding spheres screen the pairs; each pair whose spheres overlap is then tested exactly by python-fcl.
    """

    def __init__(self, scene):
        robot = scene.robot
        self.robot, self.model = robot, robot.model
        self.data = robot.model.createData()
        self.gm = robot.collision_model
        self.gd = pin.GeometryData(self.gm)
        objs = self.gm.geometryObjects
        self.names = [o.name for o in objs]
        self.moving = [g for g, o in enumerate(objs) if o.parentJoint > 0]
        self.shapes, spheres = [], []
        for o in objs:
            geom, verts = _fcl_geometry(o.geometry, o.meshScale)
            self.shapes.append(geom)
            spheres.append(_radius(geom, verts))
        self.centre = np.array([c for c, _ in spheres])
        self.radius = np.array([r for _, r in spheres])
        part = {}
        for g, o in enumerate(objs):
            q = self.model.joints[o.parentJoint].idx_q if o.parentJoint > 0 else -1
            part[g] = next((a for a in robot.spec.arm_names if q in robot.arm_idx[a] or q in robot.hand_idx[a]), "torso")
        self.hand = {a: {g for g in self.moving if self.model.joints[objs[g].parentJoint].idx_q in robot.hand_idx[a]
                         or objs[g].name.startswith(robot.spec.arm(a).hand.prefix)} for a in robot.spec.arm_names}
        self.env, centres, radii = [], [], []
        for ob in scene.environment:
            geom, verts = _fcl_geometry_of_obstacle(ob)
            c, r = _radius(geom, verts)
            self.env.append((ob.name, geom, ob.pose))
            centres.append(ob.pose[:3, :3] @ c + ob.pose[:3, 3])
            radii.append(r)
        self.env_centre, self.env_radius = np.array(centres), np.array(radii)
        self.object, verts = _mesh(scene.object_mesh), np.asarray(scene.object_mesh.vertices, float)
        self.object_centre, self.object_radius = _radius(self.object, verts)
        parents = self.model.parents
        poses = self._poses(robot.q_rest)
        pairs = [(i, j) for i in self.moving for j in range(len(objs)) if (j not in self.moving or i < j) and part[i] != part[j]
                      and objs[i].parentJoint != objs[j].parentJoint
                      and parents[objs[i].parentJoint] != objs[j].parentJoint and parents[objs[j].parentJoint] != objs[i].parentJoint
                 and not _hit(self.shapes[i], poses[i], self.shapes[j], poses[j])]
        self.pairs = (np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs]))
        self.supports = {name for name, geom, T in self.env for pose in (scene.object_initial, scene.object_final)
                         if fcl.distance(fcl.CollisionObject(self.object, _tf(pose)), fcl.CollisionObject(geom, _tf(T)),
                                         fcl.DistanceRequest(), fcl.DistanceResult()) < 0.005}

    def _poses(self, q: np.ndarray) -> list[np.ndarray]:
        pin.updateGeometryPlacements(self.model, self.data, self.gm, self.gd, q)
        return [self.gd.oMg[g].homogeneous for g in range(len(self.names))]

    def object_hits(self, q: np.ndarray, object_pose: np.ndarray) -> list[str]:
        """Names of the robot links that hit the object at q (every link: nothing holds it)."""
        return self.collisions(q, object_pose, None, None, False, only_object=True)

    def collisions(self, q: np.ndarray, object_pose: np.ndarray, holder: str | None, active: str | None,
                   near_support: bool, only_object: bool = False) -> list[str]:
        """Names of the colliding pairs at q (empty when free); `only_object`: the robot against the object alone."""
        poses = self._poses(q)
        rot = np.array([T[:3, :3] for T in poses])
        centres = np.einsum("gij,gj->gi", rot, self.centre) + np.array([T[:3, 3] for T in poses])
        ocentre = object_pose[:3, :3] @ self.object_centre + object_pose[:3, 3]
        excused = (self.hand[holder] if holder else set()) | (self.hand[active] if active else set())
        found = []
        moving = np.array(self.moving)
        near_env = np.linalg.norm(centres[moving, None] - self.env_centre[None], axis=2) < self.radius[moving, None] + self.env_radius
        for a, e in zip(*np.nonzero(near_env & (not only_object))):
            g, (name, geom, T) = moving[a], self.env[e]
            if _hit(self.shapes[g], poses[g], geom, T):
                found.append(f"{self.names[g]} with {name}")
        near_object = np.linalg.norm(centres[moving] - ocentre, axis=1) < self.radius[moving] + self.object_radius
        for g in moving[near_object]:
            if g not in excused and _hit(self.shapes[g], poses[g], self.object, object_pose):
                found.append(f"{self.names[g]} with the object")
        if only_object:
            return found
        if holder is not None:
            for e in np.flatnonzero(np.linalg.norm(self.env_centre - ocentre, axis=1) < self.object_radius + self.env_radius):
                name, geom, T = self.env[e]
                if not (near_support and name in self.supports) and _hit(self.object, object_pose, geom, T):
                    found.append(f"the object with {name}")
        i, j = self.pairs
        for k in np.flatnonzero(np.linalg.norm(centres[i] - centres[j], axis=1) < self.radius[i] + self.radius[j]):
            if _hit(self.shapes[i[k]], poses[i[k]], self.shapes[j[k]], poses[j[k]]):
                found.append(f"{self.names[i[k]]} with {self.names[j[k]]}")
        return found


def _hit(a, Ta, b, Tb) -> bool:
    return fcl.collide(fcl.CollisionObject(a, _tf(Ta)), fcl.CollisionObject(b, _tf(Tb)), fcl.CollisionRequest(), fcl.CollisionResult()) > 0


def _object_between(session, motion, k: int, q: np.ndarray) -> np.ndarray:
    """The object's pose at q on the way to sample k (which holds for the whole interval before it): carried rigidly by
    the holder's palm, else where sample k has it."""
    h = int(motion.holder[k])
    if h < 0:
        return motion.object_pose[k]
    robot = session.scene.robot
    frame = robot.palm_frame(motion.arms[h])
    grasp = np.linalg.inv(robot.frame_placement(motion.q[k], frame)) @ motion.object_pose[k]
    return robot.frame_placement(q, frame) @ grasp


def test_trajectory_passes_the_task_configurations(planned):
    session, m = planned
    scene, dg = session.scene, session.result("double_grasps")
    assert not m.failure and m.double_grasp >= 0
    k = m.double_grasp
    assert np.array_equal(m.q[0], scene.q_initial) and np.array_equal(m.q[-1], scene.q_final)
    for key, q in zip(m.keyframes[1:4], (dg.q_grasp[k], dg.q_exch[k], dg.q_place[k])):
        arms = np.concatenate([scene.robot.torso_idx] + [scene.robot.arm_idx[a] for a in m.arms])
        assert np.abs(m.q[key][arms] - q[arms]).max() < 0.05  # within the IK refinement that makes hand-overs exact
    assert list(m.phase[m.keyframes]) == [0, 0, 1, 2, 3]
    assert np.all(np.diff(m.phase) >= 0) and set(np.unique(m.phase)) == {0, 1, 2, 3}


def test_object_pose_is_continuous_and_ends_at_the_placements(planned):
    session, m = planned
    scene = session.scene
    assert np.allclose(m.object_pose[0], scene.object_initial, atol=1e-9)
    assert np.allclose(m.object_pose[-1], scene.object_final, atol=1e-9)
    step = np.linalg.norm(np.diff(m.object_pose[:, :3, 3], axis=0), axis=1)
    assert step.max() < 0.05, f"the object jumps {step.max():.3f} m between two samples"
    turn = [np.arccos(np.clip((np.trace(a[:3, :3].T @ b[:3, :3]) - 1) / 2, -1, 1)) for a, b in zip(m.object_pose[:-1], m.object_pose[1:])]
    assert max(turn) < 0.1
    # it is carried: it leaves the initial pose only in a hand, and is static exactly where nobody holds it
    static = m.holder < 0
    before = static & (np.arange(len(m.t)) < m.keyframes[1])
    assert np.allclose(m.object_pose[before], scene.object_initial)
    assert np.allclose(m.object_pose[static & (np.arange(len(m.t)) > m.keyframes[3])], scene.object_final, atol=1e-4)


def test_velocity_limits_hold(planned):
    session, m = planned
    robot = session.scene.robot
    p = session.record_of("motion")["params"]
    vmax = np.minimum(np.asarray(robot.model.velocityLimit), p["max_velocity"])
    v = np.abs(np.diff(m.q, axis=0)) / np.diff(m.t)[:, None]
    assert np.all(v <= vmax * (1 + 1e-6))
    assert np.allclose(np.diff(m.t), 1.0 / p["rate"])


def test_every_configuration_is_collision_free_by_an_independent_oracle(planned):
    session, m = planned
    oracle = Oracle(session.scene)
    arms = m.arms
    bad = []
    lifting = {int(i) for i in np.flatnonzero((m.holder >= 0) & (m.active == m.holder))}  # lift and set-down
    assert not oracle.collisions(m.q[0], m.object_pose[0], None, None, False)
    for k in range(1, len(m.t)):  # the interval before sample k belongs to sample k's motion
        holder = arms[m.holder[k]] if m.holder[k] >= 0 else None
        active = arms[m.active[k]] if m.active[k] >= 0 else None
        for s in np.linspace(0.1, 1.0, 10):
            q = m.q[k - 1] + s * (m.q[k] - m.q[k - 1])
            found = oracle.collisions(q, _object_between(session, m, k, q), holder, active, k in lifting)
            if found:
                bad.append((k, round(float(s), 1), found[:3]))
    assert not bad, f"{len(bad)} colliding configurations, first: {bad[:3]}"


def test_oracle_catches_a_collision(planned):
    """The oracle is not blind: the object pushed into the torso at a carried sample is found."""
    session, m = planned
    oracle = Oracle(session.scene)
    k = int(np.flatnonzero(m.holder >= 0)[0])
    pose = m.object_pose[k].copy()
    torso = session.scene.robot.frame_placement(m.q[k], session.scene.robot.model.frames[2].name)
    pose[:3, 3] = torso[:3, 3] - np.asarray(session.scene.object_mesh.center_mass)
    assert oracle.collisions(m.q[k], pose, None, None, False)


def test_same_seed_same_motion(planned, tmp_path):
    session, m = planned
    again = _planned(tmp_path / "b")
    for name in ("motion.npz", "motion.json"):
        assert (session.folder / name).read_bytes() == (again.folder / name).read_bytes()
