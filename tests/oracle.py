"""An independent collision oracle for tests: it shares no code with the planner's checker.

The URDFs' own collision geometry (full link meshes, not hulls; the fingers' boxes and spheres)
through python-fcl, posed by pinocchio's forward kinematics: the robot against the obstacles
(zero margin), against the object at a given pose (holding hands excepted), the object against
the obstacles, and links of different parts (each arm with its hand, the torso) against each
other, except pairs the oracle itself finds touching at rest or joined by a joint.
"""
from __future__ import annotations

import fcl
import numpy as np
import pinocchio as pin
import trimesh
from mesh_depth import ClosedMesh, surface_points

# m: how deep a touching hand's link may be in the object. The motion lets the working hand's links be up to
# `contact_penetration` (1 mm) deep between its checks (0 at them), and a touching fingertip as deep as its grasp put
# it, at most the grasp list's `contact_clearance` (1 mm: the fingertip sphere shrunk by it is clear of the object);
# the palm is put at its grasp to 0.1 mm by the motion's refinement. The oracle's link meshes lie inside the planner's
# hulls, and its surface points undercut a depth by little, so more than 1.1 mm is a hand in the object.
CONTACT_DEPTH = 1.1e-3
# m: how deep a fingertip may pass while its finger closes on the object or lets go of it. The motion does not check
# the touching fingertips then (they end on the surface by design), so one curling past a bulge of the surface dips
# under it on the way; a third of the fingertips' radius (12 mm) is let pass, a finger pushed into the object is not.
SWEEP_DEPTH = 4e-3


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


def _surface(geom, scale) -> tuple[np.ndarray, float]:
    """Points on a URDF collision shape's surface in its frame, and how far its surface lies beyond them (a sphere: its
    centre, and its radius)."""
    if hasattr(geom, "vertices"):
        tris = np.array([[t[0], t[1], t[2]] for t in (geom.tri_indices(i) for i in range(geom.num_tris))], np.int64)
        shape = trimesh.Trimesh(np.asarray(geom.vertices()) * np.asarray(scale), tris, process=False)
    elif hasattr(geom, "halfSide"):
        shape = trimesh.creation.box(extents=2 * np.asarray(geom.halfSide))
    elif hasattr(geom, "halfLength"):
        make = trimesh.creation.capsule if "Capsule" in type(geom).__name__ else trimesh.creation.cylinder
        shape = make(radius=geom.radius, height=2 * geom.halfLength)
    else:
        return np.zeros((1, 3)), float(geom.radius)
    return surface_points(shape), 0.0


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

    def __init__(self, scene, depth: float = CONTACT_DEPTH, sweep: float = SWEEP_DEPTH):
        """`depth`: how deep a link of a hand touching the object may go into it; `sweep`: a fingertip while the
        fingers close or open."""
        robot = scene.robot
        self.depth, self.sweep = depth, sweep
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
        self.posed = [fcl.CollisionObject(geom) for geom in self.shapes]  # each placed when first tested at a q (`_at`)
        self._placed: list[bool] = []
        self.centre = np.array([c for c, _ in spheres])
        self.radius = np.array([r for _, r in spheres])
        part = {}
        for g, o in enumerate(objs):
            q = self.model.joints[o.parentJoint].idx_q if o.parentJoint > 0 else -1
            part[g] = next((a for a in robot.spec.arm_names if q in robot.arm_idx[a] or q in robot.hand_idx[a]), "torso")
        self.hand = {a: {g for g in self.moving if self.model.joints[objs[g].parentJoint].idx_q in robot.hand_idx[a]
                         or objs[g].name.startswith(robot.spec.arm(a).hand.prefix)} for a in robot.spec.arm_names}
        tip_joints = {a: {self.model.frames[self.model.getFrameId(robot.spec.arm(a).hand.prefixed(f.tip_frame))].parentJoint
                          for f in robot.spec.arm(a).hand.fingers} for a in robot.spec.arm_names}
        self.tips = {a: {g for g in self.hand[a] if objs[g].parentJoint in tip_joints[a]} for a in robot.spec.arm_names}
        self.env, centres, radii = [], [], []
        for ob in scene.environment:
            geom, verts = _fcl_geometry_of_obstacle(ob)
            c, r = _radius(geom, verts)
            self.env.append((ob.name, geom, ob.pose))
            centres.append(ob.pose[:3, :3] @ c + ob.pose[:3, 3])
            radii.append(r)
        self.env_centre, self.env_radius = np.array(centres), np.array(radii)
        # a box obstacle's pose and half extents: a link's bounding sphere is near it only within its radius of the box
        # (the desk's own bounding sphere holds the whole robot)
        self.boxes = {e: (np.linalg.inv(ob.pose), np.asarray(ob.size, float) / 2) for e, ob in enumerate(scene.environment)
                      if ob.shape == "box"}
        self.env_objects = [fcl.CollisionObject(geom, _tf(T)) for _, geom, T in self.env]  # static: made once
        self.object, verts = _mesh(scene.object_mesh), np.asarray(scene.object_mesh.vertices, float)
        self.posed_object = fcl.CollisionObject(self.object)
        self.object_centre, self.object_radius = _radius(self.object, verts)
        self.closed, self.object_box = ClosedMesh(scene.object_mesh), (verts.min(axis=0), verts.max(axis=0))
        self.surface = {g: _surface(objs[g].geometry, objs[g].meshScale) for hand in self.hand.values() for g in hand}
        parents = self.model.parents
        poses = self._poses(robot.q_rest)
        pairs = [(i, j) for i in self.moving for j in range(len(objs)) if (j not in self.moving or i < j) and part[i] != part[j]
                      and objs[i].parentJoint != objs[j].parentJoint
                      and parents[objs[i].parentJoint] != objs[j].parentJoint and parents[objs[j].parentJoint] != objs[i].parentJoint
                 and not hit(self.shapes[i], poses[i], self.shapes[j], poses[j])]
        self.pairs = (np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs]))
        self.supports = {name for name, geom, T in self.env for pose in (scene.object_initial, scene.object_final)
                         if fcl.distance(fcl.CollisionObject(self.object, _tf(pose)), fcl.CollisionObject(geom, _tf(T)),
                                         fcl.DistanceRequest(), fcl.DistanceResult()) < 0.005}

    def _poses(self, q: np.ndarray) -> list[np.ndarray]:
        pin.updateGeometryPlacements(self.model, self.data, self.gm, self.gd, q)
        return [self.gd.oMg[g].homogeneous for g in range(len(self.names))]

    def _posed(self, q: np.ndarray) -> tuple[list[np.ndarray], np.ndarray]:
        """(each geometry's world pose, its bounding sphere's world centre) at q."""
        poses = self._poses(q)
        self._placed = [False] * len(poses)
        rot = np.array([T[:3, :3] for T in poses])
        return poses, np.einsum("gij,gj->gi", rot, self.centre) + np.array([T[:3, 3] for T in poses])

    def _at(self, g: int, poses: list[np.ndarray]) -> fcl.CollisionObject:
        """Geometry g's fcl object, placed at its pose at the configuration `_posed` last posed."""
        if not self._placed[g]:
            self.posed[g].setTransform(_tf(poses[g]))
            self._placed[g] = True
        return self.posed[g]

    def _environment_hits(self, poses: list[np.ndarray], centres: np.ndarray) -> list[str]:
        moving = np.array(self.moving)
        near = np.linalg.norm(centres[moving, None] - self.env_centre[None], axis=2) < self.radius[moving, None] + self.env_radius
        for e, (inverse, half) in self.boxes.items():
            local = centres[moving] @ inverse[:3, :3].T + inverse[:3, 3]
            near[:, e] &= np.linalg.norm(np.maximum(np.abs(local) - half, 0.0), axis=1) < self.radius[moving]
        return [f"{self.names[moving[a]]} with {self.env[e][0]}" for a, e in zip(*np.nonzero(near))
                if _touch(self._at(moving[a], poses), self.env_objects[e])]

    def _self_hits(self, poses: list[np.ndarray], centres: np.ndarray) -> list[str]:
        i, j = self.pairs
        near = np.flatnonzero(np.linalg.norm(centres[i] - centres[j], axis=1) < self.radius[i] + self.radius[j])
        return [f"{self.names[i[k]]} with {self.names[j[k]]}" for k in near
                if _touch(self._at(i[k], poses), self._at(j[k], poses))]

    def _object_hits(self, poses: list[np.ndarray], centres: np.ndarray, object_pose: np.ndarray,
                     excused: dict[int, float]) -> list[str]:
        """Names of the robot links that hit the object, those in `excused` only deeper than the depth it gives them."""
        moving = np.array(self.moving)
        ocentre = object_pose[:3, :3] @ self.object_centre + object_pose[:3, 3]
        near = np.linalg.norm(centres[moving] - ocentre, axis=1) < self.radius[moving] + self.object_radius
        found = []
        self.posed_object.setTransform(_tf(object_pose))
        for g in moving[near]:
            if _touch(self._at(g, poses), self.posed_object):
                if g not in excused:
                    found.append(f"{self.names[g]} with the object")
                elif (d := self.depth_in_object(g, poses[g], object_pose)) > excused[g]:
                    found.append(f"{self.names[g]} {1e3 * d:.1f} mm into the object")
        return found

    def depth_in_object(self, g: int, pose: np.ndarray, object_pose: np.ndarray) -> float:
        """How deep hand geometry g at world `pose` goes into the object at `object_pose` (m; 0 when only its points
        outside the object's bounding box are found, none of which can be inside)."""
        points, beyond = self.surface[g]
        T = np.linalg.solve(object_pose, pose)
        p = points @ T[:3, :3].T + T[:3, 3]
        if beyond == 0.0:
            p = p[np.all((p >= self.object_box[0]) & (p <= self.object_box[1]), axis=1)]
            if not len(p):
                return 0.0
        return beyond + float(self.closed.signed_distances(p).max())

    def robot_collisions(self, q: np.ndarray) -> list[str]:
        """Names of the colliding pairs of the robot alone at q (no object): its links against the obstacles and each other."""
        poses, centres = self._posed(q)
        return self._environment_hits(poses, centres) + self._self_hits(poses, centres)

    def object_hits(self, q: np.ndarray, object_pose: np.ndarray) -> list[str]:
        """Names of the robot links that hit the object at q (every link: nothing holds it)."""
        return self._object_hits(*self._posed(q), object_pose, {})

    def object_obstacle_hits(self, object_pose: np.ndarray, excused: set[str] = frozenset()) -> list[str]:
        """Names of the obstacles (those in `excused` aside) the object at `object_pose` hits."""
        ocentre = object_pose[:3, :3] @ self.object_centre + object_pose[:3, 3]
        near = np.flatnonzero(np.linalg.norm(self.env_centre - ocentre, axis=1) < self.object_radius + self.env_radius)
        return [f"the object with {self.env[e][0]}" for e in near
                if self.env[e][0] not in excused and hit(self.object, object_pose, self.env[e][1], self.env[e][2])]

    def collisions(self, q: np.ndarray, object_pose: np.ndarray, holder: str | None, active: str | None,
                   near_support: bool, closing: bool = False) -> list[str]:
        """Names of the colliding pairs at q along a motion (empty when free): the robot with the object at `object_pose`
        (the `holder`'s and the `active` hand's links may touch it, no deeper than `depth`, the active hand's fingertips
        `sweep` while its fingers move when `closing`) and, while held, the object with the obstacles (its supports
        excepted when `near_support`)."""
        poses, centres = self._posed(q)
        excused = {g: self.depth for arm in (holder, active) if arm for g in self.hand[arm]}
        if closing and active:
            excused.update(dict.fromkeys(self.tips[active], self.sweep))
        found = self._environment_hits(poses, centres) + self._object_hits(poses, centres, object_pose, excused)
        if holder is not None:
            found += self.object_obstacle_hits(object_pose, self.supports if near_support else set())
        return found + self._self_hits(poses, centres)


_REQUEST = fcl.CollisionRequest()


def hit(a, Ta, b, Tb) -> bool:
    """Whether two fcl shapes collide at these world poses."""
    return _touch(fcl.CollisionObject(a, _tf(Ta)), fcl.CollisionObject(b, _tf(Tb)))


def _touch(a: fcl.CollisionObject, b: fcl.CollisionObject) -> bool:
    """Whether two posed fcl objects collide (a fresh result each time: fcl adds its contacts to the one it is given)."""
    return fcl.collide(a, b, _REQUEST, fcl.CollisionResult()) > 0


class _Carried:
    """The object's pose at q on the way to sample k (which holds for the whole interval before it): carried rigidly by
    the holder's palm, else where sample k has it (pinocchio's kinematics in one data of its own)."""

    def __init__(self, session, motion):
        self.robot, self.motion = session.scene.robot, motion
        self.data = self.robot.model.createData()

    def grasp(self, k: int) -> tuple[str, np.ndarray] | None:
        """(the holding palm's frame, the object in that frame) at sample k; None: nothing holds it."""
        h = int(self.motion.holder[k])
        if h < 0:
            return None
        frame = self.robot.palm_frame(self.motion.arms[h])
        return frame, np.linalg.inv(self.robot.frame_placement(self.motion.q[k], frame, self.data)) @ self.motion.object_pose[k]

    def pose(self, k: int, held: tuple[str, np.ndarray] | None, q: np.ndarray) -> np.ndarray:
        if held is None:
            return self.motion.object_pose[k]
        return self.robot.frame_placement(q, held[0], self.data) @ held[1]


def motion_collisions(session, m) -> list[tuple]:
    """(sample, fraction, pairs) of every colliding configuration of a planned motion: each sample and nine more on the
    chord before it, the holding and working hands excused as `Oracle.collisions` says, the object's supports while
    it is lifted or set down (a hand holding it and working at it)."""
    oracle, carried = Oracle(session.scene), _Carried(session, m)
    arms = m.arms
    bad = []
    lifting = {int(i) for i in np.flatnonzero((m.holder >= 0) & (m.active == m.holder))}  # lift and set-down
    assert not oracle.collisions(m.q[0], m.object_pose[0], None, None, False)
    for k in range(1, len(m.t)):  # the interval before sample k belongs to sample k's motion
        holder = arms[m.holder[k]] if m.holder[k] >= 0 else None
        active = arms[m.active[k]] if m.active[k] >= 0 else None
        fingers = session.scene.robot.hand_idx[active] if active else []
        closing = bool(np.any(m.q[k - 1, fingers] != m.q[k, fingers]))
        held = carried.grasp(k)
        for s in np.linspace(0.1, 1.0, 10):
            q = m.q[k - 1] + s * (m.q[k] - m.q[k - 1])
            found = oracle.collisions(q, carried.pose(k, held, q), holder, active, k in lifting, closing)
            if found:
                bad.append((k, round(float(s), 1), found[:3]))
    return bad


def grasp_offset(session, m) -> float:
    """The farthest (m) a holding palm sits, over every held sample, from the nearest grasp of its hand's lists (the
    pick and place steps'): a hand holding the object elsewhere than its list says puts a fingertip that much deeper."""
    robot, lists = session.scene.robot, [session.result(name) for name in ("pick_grasps", "place_grasps")]
    model = robot.model
    data, worst = model.createData(), 0.0
    for k in np.flatnonzero(m.holder >= 0):
        arm = m.arms[int(m.holder[k])]
        pin.framesForwardKinematics(model, data, m.q[k])
        palm = np.linalg.solve(m.object_pose[k], data.oMf[model.getFrameId(robot.palm_frame(arm))].homogeneous)
        listed = np.concatenate([g.hand_pose[:, :3, 3] for g in lists if g.hand == arm])
        worst = max(worst, float(np.linalg.norm(listed - palm[:3, 3], axis=1).min()))
    return worst
