"""The robot: a pinocchio model composed from the spec's body URDF and two hand URDFs.

`Robot` is built once and shared read-only (like pinocchio's Model); every caller that computes
keeps its own `pin.Data`.
"""
from __future__ import annotations

import functools
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from planner.core.errors import InputError
from planner.core.paths import robot_data_share
from planner.core.results import frozen
from planner.model.robot_spec import RobotSpec, load_robot_spec, rest_configuration_of


@dataclass(frozen=True, eq=False)
class Robot:
    """A composed robot with index maps from parts (torso, arms, hands, fingers) into q."""

    spec: RobotSpec
    model: pin.Model
    collision_model: pin.GeometryModel
    visual_model: pin.GeometryModel
    lower: np.ndarray
    upper: np.ndarray
    q_rest: np.ndarray
    torso_idx: np.ndarray
    arm_idx: dict[str, np.ndarray]
    hand_idx: dict[str, np.ndarray]
    finger_idx: dict[str, dict[str, np.ndarray]]
    joint_axes: np.ndarray  # (njoints, 3) each joint's rotation axis in its own frame (row 0: the universe), for displacement bounds

    @property
    def nq(self) -> int:
        return self.model.nq

    def part_idx(self, part: str) -> np.ndarray:
        """q indices of 'torso', an arm name, '<arm>_hand', or '<arm>_hand/<finger>'."""
        if part == "torso":
            return self.torso_idx
        if part in self.arm_idx:
            return self.arm_idx[part]
        if part.endswith("_hand") and part[:-5] in self.hand_idx:
            return self.hand_idx[part[:-5]]
        arm, _, finger = part.partition("_hand/")
        if arm in self.finger_idx and finger in self.finger_idx[arm]:
            return self.finger_idx[arm][finger]
        raise KeyError(f"unknown part '{part}' (parts: {', '.join(self.part_names())})")

    def part_names(self) -> list[str]:
        names = ["torso"] if len(self.torso_idx) else []
        for arm in self.spec.arm_names:
            names += [arm, f"{arm}_hand"] + [f"{arm}_hand/{f}" for f in self.finger_idx[arm]]
        return names

    def joint_names(self) -> list[str]:
        """Names of the configuration's coordinates, in q order (all joints are 1-DoF)."""
        return [self.model.names[j] for j in range(1, self.model.njoints)]

    def frame_id(self, name: str) -> int:
        fid = self.model.getFrameId(name)
        if fid >= self.model.nframes:
            raise KeyError(f"robot '{self.spec.name}' has no frame '{name}'")
        return fid

    def palm_frame(self, arm: str) -> str:
        """The name of an arm's palm frame: where grasp hand poses are expressed."""
        hand = self.spec.arm(arm).hand
        return hand.prefixed(hand.palm_frame)

    def wrist_frame(self, arm: str) -> str:
        """The name of an arm's wrist frame: the body frame its hand is mounted on (the one meaning of 'wrist')."""
        return self.spec.arm(arm).hand.mount_frame

    def clip(self, q: np.ndarray) -> np.ndarray:
        return np.clip(q, self.lower, self.upper)

    def within_limits(self, q: np.ndarray, tol: float = 1e-9) -> bool:
        return bool(np.all(q >= self.lower - tol) and np.all(q <= self.upper + tol))

    def configuration(self, values: dict[str, float], base: np.ndarray | None = None) -> np.ndarray:
        """A configuration from joint name -> value, the rest taken from `base` (default: rest)."""
        return _configuration(self.model, values, self.q_rest if base is None else base)

    def frame_placement(self, q: np.ndarray, frame: str, data: pin.Data | None = None) -> np.ndarray:
        """4x4 world pose of a frame at q."""
        data = data or self.model.createData()
        fid = self.frame_id(frame)
        pin.framesForwardKinematics(self.model, data, q)
        return data.oMf[fid].homogeneous.copy()


def _configuration(model: pin.Model, values: dict[str, float], base: np.ndarray) -> np.ndarray:
    """A copy of `base` with the named joints set (joint name -> value)."""
    q = np.array(base, dtype=float)
    names = [model.names[j] for j in range(1, model.njoints)]
    for name, value in values.items():
        q[names.index(name)] = value
    return q


def joint_axes(model: pin.Model) -> np.ndarray:
    """(njoints, 3) each joint's rotation axis in its own frame (row 0: the universe, unused)."""
    data = model.createData()
    pin.computeJointJacobians(model, data, pin.neutral(model))
    axes = np.zeros((model.njoints, 3))
    for j in range(1, model.njoints):
        axes[j] = pin.getJointJacobian(model, data, j, pin.LOCAL)[3:, model.joints[j].idx_v]
    return axes


def _prefixed_urdf(path: Path, prefix: str) -> str:
    """The URDF's text with every link and joint name prefixed (two copies of one hand must not clash)."""
    tree = ET.parse(path)
    root = tree.getroot()
    for elem in root.iter():
        if elem.tag in ("link", "joint") and "name" in elem.attrib:
            elem.attrib["name"] = prefix + elem.attrib["name"]
        if elem.tag in ("parent", "child") and "link" in elem.attrib:
            elem.attrib["link"] = prefix + elem.attrib["link"]
        if elem.tag == "mimic" and "joint" in elem.attrib:
            elem.attrib["joint"] = prefix + elem.attrib["joint"]
    return ET.tostring(root, encoding="unicode")


def _load(urdf_text: str, source: Path) -> tuple[pin.Model, pin.GeometryModel, pin.GeometryModel]:
    dirs = [str(robot_data_share()), str(source.parent)]
    try:
        model = pin.buildModelFromXML(urdf_text)
        coll = pin.buildGeomFromUrdfString(model, urdf_text, pin.GeometryType.COLLISION, package_dirs=dirs)
        vis = pin.buildGeomFromUrdfString(model, urdf_text, pin.GeometryType.VISUAL, package_dirs=dirs)
    except (RuntimeError, ValueError) as exc:
        raise InputError(source, None, f"pinocchio could not load this URDF ({exc})") from exc
    return model, coll, vis


def _drop_geometry(geom: pin.GeometryModel, model: pin.Model, links: tuple[str, ...]) -> None:
    doomed = {model.getFrameId(link) for link in links}
    for name in [g.name for g in geom.geometryObjects if g.parentFrame in doomed]:
        geom.removeGeometryObject(name)


def _idx(model: pin.Model, names, spec: RobotSpec, field: str) -> np.ndarray:
    out = []
    for name in names:
        if not model.existJointName(name):
            raise InputError(spec.source, field, f"joint '{name}' is not in the composed robot")
        jid = model.getJointId(name)
        if model.joints[jid].nq != 1:
            raise InputError(spec.source, field, f"joint '{name}' is not a 1-DoF joint")
        out.append(model.joints[jid].idx_q)
    return np.asarray(out, dtype=int)


def joint_at(model: pin.Model, i: int) -> int:
    """The id of the 1-DoF joint at configuration index i."""
    return next(j for j in range(1, model.njoints) if model.joints[j].idx_q == i)


def robot_joint_name(model: pin.Model, i: int) -> str:
    """The name of the 1-DoF joint at configuration index i."""
    return model.names[joint_at(model, i)]


def build_robot(spec: RobotSpec) -> Robot:
    """Compose body + hands with pinocchio, lock the spec's locked joints, and index the parts."""
    try:
        body_text = spec.body_urdf.read_text()
    except UnicodeDecodeError as exc:
        raise InputError(spec.source, "body.urdf", f"'{spec.body_urdf}' is not a text file; expected a URDF") from exc
    model, coll, vis = _load(body_text, spec.body_urdf)
    for g in (coll, vis):
        _drop_geometry(g, model, spec.drop_geometry)
    for arm in spec.arms:
        hand = arm.hand
        try:
            text = _prefixed_urdf(hand.urdf, hand.prefix)
        except ET.ParseError as exc:
            raise InputError(spec.source, f"arms.{arm.name}.hand.urdf", f"'{hand.urdf}' is not a URDF (not valid XML: {exc})") from exc
        hmodel, hcoll, hvis = _load(text, hand.urdf)
        if not model.existFrame(hand.mount_frame):
            raise InputError(spec.source, f"arms.{arm.name}.hand.mount_frame", f"no frame '{hand.mount_frame}' in the body URDF")
        mount = pin.SE3(pin.rpy.rpyToMatrix(*hand.mount_rpy), np.array(hand.mount_xyz))
        fid = model.getFrameId(hand.mount_frame)
        try:
            model_c, coll = pin.appendModel(model, hmodel, coll, hcoll, fid, mount)
        except ValueError as exc:  # pinocchio: "The two models have conflicting frame names."
            raise InputError(spec.source, f"arms.{arm.name}.hand.prefix", f"the hand's link and joint names, prefixed with "
                             f"'{hand.prefix}', clash with names already in the robot ({exc}); give each hand its own prefix") from exc
        _, vis = pin.appendModel(model, hmodel, vis, hvis, fid, mount)
        model = model_c
    base = pin.SE3(pin.rpy.rpyToMatrix(*spec.base_rpy), np.array(spec.base_xyz))
    for j in range(1, model.njoints):
        if model.parents[j] == 0:
            model.jointPlacements[j] = base * model.jointPlacements[j]
    for i, f in enumerate(model.frames):
        if f.parentJoint == 0:
            f.placement = base * f.placement
            model.frames[i] = f
    for g in (coll, vis):
        for obj in g.geometryObjects:
            if obj.parentJoint == 0:
                obj.placement = base * obj.placement
    if spec.locked_joints:
        names = [n for n, _ in spec.locked_joints]
        for n in names:
            if not model.existJointName(n):
                raise InputError(spec.source, "body.locked_joints", f"joint '{n}' is not in the body URDF")
        q_ref = pin.neutral(model)
        ids = [model.getJointId(n) for n in names]
        for jid, (name, value) in zip(ids, spec.locked_joints):
            i = model.joints[jid].idx_q
            lo, hi = model.lowerPositionLimit[i], model.upperPositionLimit[i]
            if not lo - 1e-9 <= value <= hi + 1e-9:
                raise InputError(spec.source, f"body.locked_joints.{name}",
                                 f"joint '{name}' locked at {value}, outside its limits [{lo:.4g}, {hi:.4g}]")
            q_ref[i] = value
        model, (coll, vis) = pin.buildReducedModel(model, [coll, vis], ids, q_ref)
    if model.nq != model.nv:
        raise InputError(spec.source, "body", "only revolute/prismatic joints are supported (nq must equal nv)")
    for g in (coll, vis):
        for obj in g.geometryObjects:
            if obj.parentFrame >= model.nframes:
                obj.parentFrame = 0
    torso_idx = _idx(model, spec.torso_joints, spec, "body.torso_joints")
    arm_idx, hand_idx, finger_idx = {}, {}, {}
    for arm in spec.arms:
        arm_idx[arm.name] = _idx(model, arm.joints, spec, f"arms.{arm.name}.joints")
        finger_idx[arm.name] = {
            f.name: _idx(model, [arm.hand.prefixed(j) for j in f.joints], spec, f"arms.{arm.name}.hand.fingers")
            for f in arm.hand.fingers
        }
        hand_idx[arm.name] = np.concatenate(list(finger_idx[arm.name].values()))
        for f in arm.hand.fingers:
            if not model.existFrame(arm.hand.prefixed(f.tip_frame)):
                raise InputError(spec.source, f"arms.{arm.name}.hand.fingers", f"no tip frame '{f.tip_frame}' in {arm.hand.urdf.name}")
        if not model.existFrame(arm.hand.prefixed(arm.hand.palm_frame)):
            raise InputError(spec.source, f"arms.{arm.name}.hand.palm_frame", f"no frame '{arm.hand.palm_frame}' in {arm.hand.urdf.name}")
        if not model.existFrame(arm.shoulder_frame):
            raise InputError(spec.source, f"arms.{arm.name}.shoulder_frame", f"no frame '{arm.shoulder_frame}' in the body URDF")
    for pair in spec.allowed_collisions:
        for link in pair:
            if not model.existFrame(link):
                raise InputError(spec.source, "body.allowed_collisions", f"link '{link}' is not in the composed robot")
    listed = [("body.torso_joints", torso_idx)] + [(f"arms.{a}.joints", i) for a, i in arm_idx.items()]
    listed += [(f"arms.{a}.hand.fingers", i) for a, i in hand_idx.items()]
    owner: dict[int, str] = {}
    for fld, idx in listed:
        for i in idx.tolist():
            if i in owner:
                name = robot_joint_name(model, i)
                raise InputError(spec.source, owner[i], f"joint '{name}' is also listed in {fld}: a joint belongs to one part")
            owner[i] = fld
    covered = np.concatenate([torso_idx, *arm_idx.values(), *hand_idx.values()])
    if sorted(covered.tolist()) != list(range(model.nq)):
        names = [model.names[j] for j in range(1, model.njoints) if model.joints[j].idx_q not in covered]
        raise InputError(spec.source, "body.locked_joints", f"joints belong to no part; lock them or name them: {', '.join(names)}")
    lower = model.lowerPositionLimit.copy()
    upper = model.upperPositionLimit.copy()
    q_rest = _configuration(model, rest_configuration_of(spec), np.clip(np.zeros(model.nq), lower, upper))
    bad = [i for i, (v, lo, hi) in enumerate(zip(q_rest, lower, upper)) if not lo - 1e-9 <= v <= hi + 1e-9]
    if bad:
        fld = owner[bad[0]].replace(".joints", ".rest").replace(".hand.fingers", ".hand.fingers.open").replace("torso_joints", "torso_rest")
        names = ", ".join(f"{robot_joint_name(model, i)} = {q_rest[i]:.4g} not in [{lower[i]:.4g}, {upper[i]:.4g}]" for i in bad)
        raise InputError(spec.source, fld, f"rest configuration outside the joint limits: {names}")
    return Robot(spec, model, coll, vis, frozen(lower), frozen(upper), frozen(q_rest), frozen(torso_idx),
                 {a: frozen(i) for a, i in arm_idx.items()}, {a: frozen(i) for a, i in hand_idx.items()},
                 {a: {f: frozen(i) for f, i in fi.items()} for a, fi in finger_idx.items()}, frozen(joint_axes(model)))


@functools.lru_cache(maxsize=8)
def load_robot(path: str | Path) -> Robot:
    """Load a spec and build its robot (cached per path: the Robot is read-only)."""
    return build_robot(load_robot_spec(path))
