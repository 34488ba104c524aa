"""A session's motion as a trajectory file another tool reads: JSON in the shape of a ROS `trajectory_msgs/JointTrajectory`
(plus regrasp's own fields beside it), or CSV with a header. docs/sessions.md describes both formats.

Every sample of the motion is one point: its time, the positions (q, in the robot model's joint order), the velocities
and accelerations of the timed trajectory there (a session older than them stores neither: its velocities are central
finite differences of the samples and its accelerations are left out), the phase, the arm holding the object and the
object's pose. Numbers are written with every digit (they read back equal to `motion.npz`)."""
from __future__ import annotations

import csv
import io
import json
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from planner.core.errors import InputError, RegraspError
from planner.core.results import atomic_write_text
from planner.core.session import Session
from planner.model.robot import Robot
from planner.motion.result import Motion

FORMATS = (".json", ".csv")
FRAME = "world"  # the frame of the object's pose and of the robot's base (the task's world frame)
POSE_COLUMNS = ("object_x", "object_y", "object_z", "object_qx", "object_qy", "object_qz", "object_qw")
SPREADSHEET_FORMULA = ("=", "+", "-", "@", "\t", "\r")  # a text cell starting so is run as a formula by spreadsheets
KEYFRAMES = ("initial", "grasp", "exchange", "place", "final")  # `Motion.keyframes`, in order


@dataclass(frozen=True)
class TrajectoryPoints:
    """The motion's samples as a trajectory: joint names, times (s), positions, velocities and accelerations (n, joints;
    no rows of accelerations when the session has none), each sample's phase name and holding arm ('' when none), and
    the object's pose as position and quaternion (x, y, z, w)."""

    joint_names: tuple[str, ...]
    t: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray
    phases: tuple[str, ...]
    holders: tuple[str, ...]
    object_xyz: np.ndarray
    object_xyzw: np.ndarray
    keyframes: dict[str, int]


def joint_names_of(motion: Motion, robot: Robot, source: Path) -> tuple[str, ...]:
    """The names of q's columns: those the motion result stores, which must be the robot model's; the model's when the
    result is older than the field (`source`, the result's file, is named when they disagree)."""
    names = tuple(robot.joint_names())
    if motion.joint_names and tuple(motion.joint_names) != names:
        raise InputError(source, "joint_names", f"expected the robot's {len(names)} joint names in the model's order "
                                                f"({', '.join(names[:3])}, ...), got {len(motion.joint_names)} others")
    return names


def finite_difference_velocities(t: np.ndarray, q: np.ndarray) -> np.ndarray:
    """dq/dt at every sample: central differences inside, one-sided at the ends (zero for a single sample)."""
    if len(t) < 2:
        return np.zeros_like(q)
    return np.gradient(q, t, axis=0)


def trajectory_of(session: Session) -> TrajectoryPoints:
    """The motion of a saved session as its points; a RegraspError when it has no motion to write."""
    if "motion" not in session.finished():
        raise RegraspError(f"{session.folder}: the session has no motion (run the motion step first)")
    motion: Motion = session.result("motion")
    if not len(motion.t):
        raise RegraspError(f"{session.folder}: the motion step failed, there is no trajectory to write ({motion.failure})")
    names = joint_names_of(motion, session.scene.robot, session.folder / "motion.json")
    arms = [str(a) for a in motion.arms]
    holders = tuple(arms[h] if 0 <= h < len(arms) else "" for h in motion.holder.tolist())
    keys = {name: int(i) for name, i in zip(KEYFRAMES, motion.keyframes.tolist())}
    timed = len(motion.qd) == len(motion.t) and len(motion.qdd) == len(motion.t)  # else a session older than them
    velocities = motion.qd if timed else finite_difference_velocities(motion.t, motion.q)
    accelerations = motion.qdd if timed else np.zeros((0, len(names)))
    return TrajectoryPoints(names, motion.t, motion.q, velocities, accelerations,
                      tuple(motion.phase_name(p) for p in motion.phase.tolist()), holders, motion.object_pose[:, :3, 3],
                      Rotation.from_matrix(motion.object_pose[:, :3, :3]).as_quat(), keys)


def duration(seconds: float) -> dict[str, int]:
    """A time as ROS's builtin_interfaces/Duration: whole seconds and nanoseconds (0 to 999,999,999)."""
    ns = round(seconds * 1e9)
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


def _floats(row: np.ndarray) -> list[float]:
    return [float(x) for x in row]


def trajectory_json(tr: TrajectoryPoints) -> str:
    """JointTrajectory's fields (header, joint_names, points with positions, velocities, accelerations (empty when
    unknown), time_from_start), then regrasp's per-point lists beside them (time, phase, holder, object_pose as
    geometry_msgs/Pose) and the keyframes."""
    acc = [_floats(a) for a in tr.accelerations] if len(tr.accelerations) else [[] for _ in tr.t]
    points = [{"positions": _floats(p), "velocities": _floats(v), "accelerations": a, "effort": [], "time_from_start": duration(t)}
              for t, p, v, a in zip(tr.t.tolist(), tr.positions, tr.velocities, acc)]
    poses = [{"position": dict(zip("xyz", _floats(x))), "orientation": dict(zip("xyzw", _floats(r)))}
             for x, r in zip(tr.object_xyz, tr.object_xyzw)]
    data = {"header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": FRAME}, "joint_names": list(tr.joint_names), "points": points,
            "time": tr.t.tolist(), "phase": list(tr.phases), "holder": [h or None for h in tr.holders], "object_pose": poses,
            "keyframes": tr.keyframes}
    return json.dumps(data, separators=(",", ":"))


def _cell(text: str) -> str:
    """A text cell a spreadsheet shows as text (a leading ' before what it would run as a formula)."""
    return f"'{text}" if text.startswith(SPREADSHEET_FORMULA) else text


def csv_header(tr: TrajectoryPoints) -> list[str]:
    """time, phase, holder, the object's pose, then position:JOINT, velocity:JOINT and (when known)
    acceleration:JOINT per joint in the model's order."""
    kinds = ("position", "velocity", "acceleration") if len(tr.accelerations) else ("position", "velocity")
    return ["time", "phase", "holder", *POSE_COLUMNS, *(_cell(f"{kind}:{n}") for kind in kinds for n in tr.joint_names)]


def _csv_rows(tr: TrajectoryPoints) -> Iterator[list]:
    for i, t in enumerate(tr.t.tolist()):
        yield [repr(t), tr.phases[i], _cell(tr.holders[i]), *map(repr, _floats(tr.object_xyz[i])), *map(repr, _floats(tr.object_xyzw[i])),
               *map(repr, _floats(tr.positions[i])), *map(repr, _floats(tr.velocities[i])),
               *(map(repr, _floats(tr.accelerations[i])) if len(tr.accelerations) else ())]


def trajectory_csv(tr: TrajectoryPoints) -> str:
    """One header line, then one line per sample (numbers with every digit, as Python writes them)."""
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(csv_header(tr))
    writer.writerows(_csv_rows(tr))
    return out.getvalue()


def trajectory_text(tr: TrajectoryPoints, suffix: str) -> str:
    """The trajectory in the format a file name's suffix ('.json' or '.csv') names."""
    return trajectory_json(tr) if suffix == ".json" else trajectory_csv(tr)


def output_path(path: Path, option: str, suffixes: tuple[str, ...], force: bool) -> Path:
    """`path` if a command may write there: the suffix one of `suffixes`, and no existing file unless `force`."""
    if path.suffix.lower() not in suffixes:
        raise RegraspError(f"{option} {path}: expected a file name ending in {' or '.join(suffixes)}")
    if path.is_dir():
        raise RegraspError(f"{option} {path}: a folder; expected a file name")
    if (path.exists() or path.is_symlink()) and not force:
        raise RegraspError(f"{option} {path}: the file exists; use --force to replace it")
    return path


def write_trajectory(session_dir: Path, out: Path) -> int:
    """Write the motion of a saved session to `out` (.json or .csv, checked by `output_path` first); returns the points."""
    tr = trajectory_of(Session.open(session_dir))
    atomic_write_text(out, trajectory_text(tr, out.suffix.lower()))
    return len(tr.t)

