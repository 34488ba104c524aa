"""A standalone hand (palm frame = hand frame) read from a robot spec: finger chains, batched FK, Jacobians and IK.

Each finger is a serial chain of revolute joints starting at the hand's root link. Forward
kinematics, Jacobians and damped-least-squares IK run on numpy arrays of many configurations at
once: the grasp planner solves IK for a whole batch of candidate contacts per finger (an order of
magnitude cheaper per target than pinocchio's one-at-a-time IK). Collision shapes are the hand
URDF's collision geometries (meshes replaced by their convex hulls), posed in the hand frame.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from planner.collision.shapes import Geometry, convex_geometry, is_sphere
from planner.core.errors import InputError
from planner.model.robot import _load
from planner.model.robot_spec import HandSpec

AXES = {"JointModelRX": (1.0, 0.0, 0.0), "JointModelRY": (0.0, 1.0, 0.0), "JointModelRZ": (0.0, 0.0, 1.0)}
TIP_MATCH = 1e-3  # m: a sphere geometry centred this close to the tip frame is the fingertip itself


@dataclass(frozen=True, eq=False)
class Shape:
    """One collision geometry of the hand: on link `link` of its finger (-1: the palm/hand body)."""

    name: str
    link: int
    placement: np.ndarray  # 4x4 in its joint's frame (the hand frame for the body)
    geometry: Geometry
    is_tip: bool


@dataclass(frozen=True, eq=False)
class FingerChain:
    """A finger: k revolute joints in series from the hand frame to the fingertip."""

    name: str
    joints: tuple[str, ...]
    placements: np.ndarray  # (k, 4, 4): joint i's frame in joint i-1's (joint 0's in the hand frame), at q = 0
    axes: np.ndarray  # (k, 3): rotation axes in the joints' own frames
    lower: np.ndarray
    upper: np.ndarray
    open_q: np.ndarray
    tip: np.ndarray  # (4, 4): the tip frame in the last joint's frame
    tip_radius: float
    shapes: tuple[Shape, ...]

    @property
    def dof(self) -> int:
        return len(self.joints)

    def reduced_limits(self, margin: float) -> tuple[np.ndarray, np.ndarray]:
        """Joint limits moved inwards by `margin` of each range at both ends (no stretched fingers)."""
        span = self.upper - self.lower
        return self.lower + margin * span, self.upper - margin * span

    @functools.cached_property
    def _terms(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per joint: M_R, M_R K, M_R K^2 (so that M_R Rot(q) = A + sin q B + (1 - cos q) C), each (k, 3, 3, 1) to
        broadcast over configurations on the last axis, and M_t."""
        K = _skew(self.axes)
        A = self.placements[:, :3, :3]
        return A[..., None], (A @ K)[..., None], (A @ K @ K)[..., None], self.placements[:, :3, 3]

    @functools.cached_property
    def _axis_columns(self) -> tuple[np.ndarray, np.ndarray] | None:
        """Per joint, the column of its frame's rotation its axis picks and the axis's one nonzero component, when every
        axis lies along a coordinate axis (R @ axis is then that column times it, rounded the same); None otherwise."""
        if np.any(np.count_nonzero(self.axes, axis=1) != 1):
            return None
        column = np.argmax(np.abs(self.axes), axis=1)
        return column, self.axes[np.arange(self.dof), column][:, None]

    def chain(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Joint rotations (N, k, 3, 3) and origins (N, k, 3) in the hand frame for configurations q (N, k)."""
        q = np.atleast_2d(q)
        A, B, C, t = self._terms
        s, c = np.sin(q).T[:, None, None], (1.0 - np.cos(q)).T[:, None, None]  # (k, 1, 1, N): long inner loops
        local = np.ascontiguousarray(np.moveaxis(A + s * B + c * C, 3, 0))
        R = np.empty((len(q), self.dof, 3, 3))
        p = np.empty((len(q), self.dof, 3))
        R_prev, p_prev = local[:, 0], t[0]  # the hand frame is the identity: its products are exact copies
        R[:, 0], p[:, 0] = R_prev, p_prev
        for j in range(1, self.dof):
            p_prev = p_prev + R_prev @ t[j]
            R_prev = R_prev @ local[:, j]
            R[:, j], p[:, j] = R_prev, p_prev
        return R, p

    def frames(self, q: np.ndarray) -> np.ndarray:
        """(N, k, 4, 4) joint frames in the hand frame for configurations q (N, k)."""
        R, p = self.chain(q)
        out = np.zeros(R.shape[:2] + (4, 4))
        out[..., :3, :3], out[..., :3, 3], out[..., 3, 3] = R, p, 1.0
        return out

    def tip_positions(self, q: np.ndarray) -> np.ndarray:
        """(N, 3) fingertip (tip-sphere centre) positions in the hand frame."""
        R, p = self.chain(q)
        return R[:, -1] @ self.tip[:3, 3] + p[:, -1]

    def jacobians(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Fingertip positions (N, 3) and their position Jacobians (N, 3, k) in the hand frame."""
        R, p = self.chain(q)
        tips = R[:, -1] @ self.tip[:3, 3] + p[:, -1]
        if self._axis_columns is None:
            axes = (R @ self.axes[:, :, None])[..., 0]
        else:
            column, sign = self._axis_columns
            axes = R.swapaxes(-1, -2)[:, np.arange(self.dof), column] * sign
        J = _cross(axes, tips[:, None, :] - p)
        return tips, J.transpose(0, 2, 1)

    def ik(self, targets: np.ndarray, q0: np.ndarray, lower: np.ndarray, upper: np.ndarray, tolerance: float,
           iterations: int = 10, damping: float = 1e-3,
           groups: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Batched damped least squares within [lower, upper]: configurations (N, k), their tip errors (N,) and
        fingertip Jacobians (N, 3, k).

        Rows of one group (`groups`, (N,) labels; one group by default) stop together, once every tip of the group
        is within `tolerance` (m) or `iterations` are spent: many independent batches are solved in one call, each
        row's steps the same as in a call of its group alone. A row's tip and Jacobian come from its last
        evaluation when it has not moved since (each row's kinematics is the same in any batch)."""
        q = np.clip(np.array(q0, dtype=float), lower, upper)
        eye = damping**2 * np.eye(3)
        label = np.zeros(len(q), int) if groups is None else np.unique(groups, return_inverse=True)[1].ravel()
        tips, jacobians = np.empty((len(q), 3)), np.empty((len(q), 3, self.dof))
        active = moved = np.arange(len(q))
        for _ in range(iterations):
            tips[active], jacobians[active] = self.jacobians(q[active])
            err = targets[active] - tips[active]
            worst = np.zeros(label.max(initial=0) + 1)
            np.maximum.at(worst, label[active], np.einsum("ij,ij->i", err, err))
            moving = worst[label[active]] >= tolerance**2
            moved = active[:0]
            if not moving.any():
                break
            active, err = active[moving], err[moving]
            J = jacobians[active]
            step = np.linalg.solve(J @ J.transpose(0, 2, 1) + eye, err[:, :, None])
            q[active] = np.clip(q[active] + (J.transpose(0, 2, 1) @ step)[:, :, 0], lower, upper)
            moved = active
        if len(moved):
            tips[moved], jacobians[moved] = self.jacobians(q[moved])
        return q, np.linalg.norm(targets - tips, axis=1), jacobians

    def shape_poses(self, q: np.ndarray) -> np.ndarray:
        """(N, s, 4, 4) poses of the finger's shapes in the hand frame."""
        F = self.frames(q)
        return np.stack([F[:, s.link] @ s.placement for s in self.shapes], axis=1)


@dataclass(frozen=True, eq=False)
class HandModel:
    """A hand: its fingers (spec order), the thumb's index, and the palm/body shapes in the hand frame."""

    spec: HandSpec
    fingers: tuple[FingerChain, ...]
    body: tuple[Shape, ...]

    @property
    def finger_names(self) -> tuple[str, ...]:
        return tuple(f.name for f in self.fingers)

    @property
    def thumb_first(self) -> tuple[int, ...]:
        """Finger indices in planning order: the thumb, then the others in spec order."""
        t = self.finger_names.index(self.spec.thumb)
        return (t,) + tuple(i for i in range(len(self.fingers)) if i != t)

    @property
    def dof(self) -> int:
        return sum(f.dof for f in self.fingers)

    @property
    def open_q(self) -> np.ndarray:
        return np.concatenate([f.open_q for f in self.fingers])

    def split(self, q: np.ndarray) -> list[np.ndarray]:
        """A whole-hand configuration (spec finger order) cut into per-finger configurations."""
        return np.split(np.asarray(q, float), np.cumsum([f.dof for f in self.fingers])[:-1])

    def shape_poses(self, q: np.ndarray) -> list[tuple[Shape, np.ndarray]]:
        """Every collision shape of the hand with its 4x4 pose in the hand frame at hand configuration q."""
        out = [(s, s.placement) for s in self.body]
        for finger, qf in zip(self.fingers, self.split(q)):
            out += list(zip(finger.shapes, finger.shape_poses(qf[None])[0]))
        return out


def _skew(v: np.ndarray) -> np.ndarray:
    """(k, 3, 3) cross-product matrices of vectors (k, 3)."""
    z = np.zeros(len(v))
    return np.stack([np.stack([z, -v[:, 2], v[:, 1]], -1), np.stack([v[:, 2], z, -v[:, 0]], -1),
                     np.stack([-v[:, 1], v[:, 0], z], -1)], axis=1)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b over the last axis (np.cross costs more in call overhead on small batches)."""
    return a[..., [1, 2, 0]] * b[..., [2, 0, 1]] - a[..., [2, 0, 1]] * b[..., [1, 2, 0]]


def _axis(model: pin.Model, jid: int, spec: HandSpec) -> np.ndarray:
    kind = model.joints[jid].shortname()
    if kind in AXES:
        return np.array(AXES[kind])
    if kind == "JointModelRevoluteUnaligned":
        return np.asarray(model.joints[jid].extract().axis, float)
    raise InputError(spec.urdf, None, f"joint '{model.names[jid]}' is a {kind}: finger joints must be revolute")


def build_hand_model(spec: HandSpec) -> HandModel:
    """Read the hand URDF named by a spec into finger chains and shapes, expressed in the palm frame."""
    model, collision, _ = _load(spec.urdf.read_text(), spec.urdf)
    if not model.existFrame(spec.palm_frame):
        raise InputError(spec.urdf, None, f"no palm frame '{spec.palm_frame}'")
    palm = model.frames[model.getFrameId(spec.palm_frame)]
    if palm.parentJoint != 0:
        raise InputError(spec.urdf, None, f"the palm frame '{spec.palm_frame}' must be on the hand's root link")
    to_palm = palm.placement.inverse()
    owner: dict[int, tuple[int, int]] = {}
    chains = []
    for fi, f in enumerate(spec.fingers):
        ids = []
        for name in f.joints:
            if not model.existJointName(name):
                raise InputError(spec.urdf, None, f"finger '{f.name}': no joint '{name}'")
            ids.append(model.getJointId(name))
        for a, b in zip([0] + ids[:-1], ids):
            if model.parents[b] != a:
                raise InputError(spec.urdf, None, f"finger '{f.name}': joint '{model.names[b]}' does not follow "
                                                  f"'{model.names[a]}': a finger must be a serial chain from the hand's root")
        owner.update({jid: (fi, k) for k, jid in enumerate(ids)})
        placements = np.stack([model.jointPlacements[j].homogeneous for j in ids])
        placements[0] = (to_palm * model.jointPlacements[ids[0]]).homogeneous
        idx = [model.joints[j].idx_q for j in ids]
        if not model.existFrame(f.tip_frame):
            raise InputError(spec.urdf, None, f"finger '{f.name}': no tip frame '{f.tip_frame}'")
        tip_frame = model.frames[model.getFrameId(f.tip_frame)]
        if tip_frame.parentJoint != ids[-1]:
            raise InputError(spec.urdf, None, f"finger '{f.name}': tip frame '{f.tip_frame}' is not on its last joint")
        chains.append(dict(name=f.name, joints=f.joints, placements=placements,
                           axes=np.stack([_axis(model, j, spec) for j in ids]),
                           lower=model.lowerPositionLimit[idx].copy(), upper=model.upperPositionLimit[idx].copy(),
                           open_q=np.asarray(f.open, float), tip=tip_frame.placement.homogeneous, tip_radius=f.tip_radius,
                           shapes=[]))
    body = []
    for obj in collision.geometryObjects:
        if obj.parentJoint == 0:
            body.append(Shape(obj.name, -1, (to_palm * obj.placement).homogeneous, convex_geometry(obj), False))
            continue
        if obj.parentJoint not in owner:
            raise InputError(spec.urdf, None, f"geometry '{obj.name}' hangs on joint '{model.names[obj.parentJoint]}', "
                                              "which belongs to no finger of the spec")
        fi, k = owner[obj.parentJoint]
        chain = chains[fi]
        placement = obj.placement.homogeneous
        is_tip = (is_sphere(obj.geometry) and k == len(chain["joints"]) - 1
                  and np.linalg.norm(placement[:3, 3] - chain["tip"][:3, 3]) < TIP_MATCH)
        chain["shapes"].append(Shape(obj.name, k, placement, convex_geometry(obj), bool(is_tip)))
    fingers = tuple(FingerChain(**{**c, "shapes": tuple(c["shapes"])}) for c in chains)
    for f in fingers:
        if not np.all((f.open_q >= f.lower - 1e-9) & (f.open_q <= f.upper + 1e-9)):
            raise InputError(spec.urdf, None, f"finger '{f.name}': open configuration outside the joint limits")
    return HandModel(spec, fingers, tuple(body))


@functools.lru_cache(maxsize=8)
def load_hand_model(spec: HandSpec) -> HandModel:
    """The hand model of a spec (built once per spec; read-only)."""
    return build_hand_model(spec)
