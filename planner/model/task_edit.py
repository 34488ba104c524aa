"""Edits of a task's data (what a task file holds), each giving new data that `scene_from_dict` loads: the object's
placements put down on the support under them, the robot spec, the object's mesh, obstacles moved, added or removed.

The workbench's task editor calls these; they know nothing of a GUI. A placement keeps the roll and pitch it had (the
face the object stands on) and takes only the heading asked for; its height comes from the support.
"""
from __future__ import annotations

import copy
from typing import Any

import numpy as np
import pinocchio as pin

from planner.core.errors import RegraspError
from planner.model.environment import Environment
from planner.model.task import MAX_COORDINATE, MAX_OBSTACLES, Scene

TaskData = dict[str, Any]
PLACEMENTS = ("initial", "final")
MAX_STEP = 0.1  # m: a placement is put on the highest support at most this far above where it is held (a small step up)
DIGITS = 4  # decimals kept of a coordinate (0.1 mm) or an angle (0.1 mrad): a dragged pose is written readably
NEW_SIZES = {"box": [0.1, 0.1, 0.1], "cylinder": [0.05, 0.1]}  # m: an added obstacle's size (box x y z; radius, length)
NEW_COLOR = [140, 140, 150]


def _round(values: Any) -> list[float]:
    """Numbers rounded to DIGITS decimals (-0.0 written as 0.0)."""
    return [round(float(v), DIGITS) + 0.0 for v in values]


def support_top(environment: Environment, x: float, y: float, below: float) -> float:
    """The height of the highest upward-facing obstacle surface over the point (x, y) that lies at most `below`; 0 (the
    floor) when there is none."""
    tops = [0.0]
    for obstacle in environment:
        triangles = obstacle.to_trimesh().triangles  # (n, 3, 3), world frame
        a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
        up = np.cross(b - a, c - a)[:, 2] > 1e-12  # counter-clockwise seen from above: facing up
        d = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
        ok = up & (np.abs(d) > 1e-12)
        d = np.where(ok, d, 1.0)
        u = ((x - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (y - a[:, 1])) / d
        v = ((b[:, 0] - a[:, 0]) * (y - a[:, 1]) - (x - a[:, 0]) * (b[:, 1] - a[:, 1])) / d
        inside = ok & (u >= 0) & (v >= 0) & (u + v <= 1)
        z = a[:, 2] + u * (b[:, 2] - a[:, 2]) + v * (c[:, 2] - a[:, 2])
        tops += [float(h) for h in z[inside] if h <= below + 1e-9]
    return max(tops)


def _finite(values: Any, count: int, what: str) -> list[float]:
    array = np.asarray(values, dtype=float).reshape(-1)
    if array.shape != (count,) or not np.all(np.isfinite(array)):
        raise RegraspError(f"{what}: expected {count} finite numbers, got {values!r:.80}")
    return [float(v) for v in array]


def rest_on_support(scene: Scene, which: str, xyz: Any, yaw: float) -> dict[str, list[float]]:
    """The placement `which` (initial or final) held at `xyz` with heading `yaw` (rad), put down: its roll and pitch as in
    the task, its lowest point on the highest support at most MAX_STEP above the held lowest point."""
    if which not in PLACEMENTS:
        raise RegraspError(f"placement: expected one of {', '.join(PLACEMENTS)}, got {which!r}")
    x, y, z = _finite(xyz, 3, f"the {which} placement's position")
    (yaw,) = _finite([yaw], 1, f"the {which} placement's heading")
    if max(abs(x), abs(y), abs(z)) > MAX_COORDINATE:
        raise RegraspError(f"the {which} placement: expected coordinates within {MAX_COORDINATE:g} m of the robot")
    T = scene.object_initial if which == "initial" else scene.object_final
    roll, pitch, _ = pin.rpy.matrixToRpy(np.asarray(T[:3, :3], float))
    yaw = float(np.arctan2(np.sin(yaw), np.cos(yaw)))
    tilted = pin.rpy.rpyToMatrix(float(roll), float(pitch), 0.0)
    low = float((np.asarray(scene.object_mesh.vertices) @ tilted.T)[:, 2].min())  # the heading turns about z: no change
    top = support_top(scene.environment, x, y, z + low + MAX_STEP)
    return {"xyz": _round([x, y, top - low]), "rpy": _round([roll, pitch, yaw])}


def with_placement(data: TaskData, which: str, placement: dict[str, list[float]]) -> TaskData:
    """The task with the object's `which` placement replaced."""
    data = copy.deepcopy(data)
    data["object"][which] = placement
    return data


def with_robot(data: TaskData, robot: str, joint_names: list[str]) -> tuple[TaskData, list[str]]:
    """The task on another robot spec (its file `robot`, whose joints are `joint_names`): the start and end
    configurations keep the joints the new robot has; the names of those dropped are returned."""
    data = copy.deepcopy(data)
    data["robot"] = robot
    dropped: list[str] = []
    for key in ("robot_initial", "robot_final"):
        joints = data.get(key, {}).get("joints", {})
        dropped += [name for name in joints if name not in joint_names]
        if joints:
            data[key]["joints"] = {name: value for name, value in joints.items() if name in joint_names}
    return data, sorted(set(dropped))


def with_object_mesh(data: TaskData, mesh: str, up: str = "z") -> TaskData:
    """The task with another object mesh (a file reference, in metres, its up axis `up`: a scale given before goes)."""
    data = copy.deepcopy(data)
    data["object"]["mesh"] = mesh
    data["object"].pop("scale", None)
    data["object"].pop("up", None)
    if up != "z":
        data["object"]["up"] = up
    return data


def _index(data: TaskData, name: str) -> int:
    names = [o.get("name") for o in data.get("obstacles", [])]
    if name not in names:
        raise RegraspError(f"the task has no obstacle named {name!r}")
    return names.index(name)


def with_obstacle_pose(data: TaskData, name: str, xyz: Any, yaw: float) -> TaskData:
    """The task with obstacle `name` moved to `xyz`, turned to heading `yaw` about the vertical (its roll and pitch kept)."""
    position = _finite(xyz, 3, f"obstacle {name}'s position")
    (yaw,) = _finite([yaw], 1, f"obstacle {name}'s heading")
    if max(map(abs, position)) > MAX_COORDINATE:
        raise RegraspError(f"obstacle {name}: expected coordinates within {MAX_COORDINATE:g} m of the robot")
    data = copy.deepcopy(data)
    obstacle = data["obstacles"][_index(data, name)]
    roll, pitch, _ = obstacle.get("rpy", [0.0, 0.0, 0.0])
    obstacle["xyz"] = _round(position)
    obstacle["rpy"] = _round([roll, pitch, np.arctan2(np.sin(yaw), np.cos(yaw))])
    return data


def with_obstacle_size(data: TaskData, name: str, size: Any) -> TaskData:
    """The task with box or cylinder obstacle `name` resized (the loader checks the size's range)."""
    data = copy.deepcopy(data)
    obstacle = data["obstacles"][_index(data, name)]
    if obstacle.get("shape") not in NEW_SIZES:
        raise RegraspError(f"obstacle {name}: only boxes and cylinders are resized here, not a {obstacle.get('shape')}")
    obstacle["size"] = _round(_finite(size, len(NEW_SIZES[obstacle["shape"]]), f"obstacle {name}'s size"))
    return data


def with_new_obstacle(data: TaskData, shape: str, xyz: Any) -> tuple[TaskData, str]:
    """The task with a new box or cylinder standing at `xyz` (its base there); the new obstacle's name is returned."""
    if shape not in NEW_SIZES:
        raise RegraspError(f"new obstacle: expected one of {', '.join(NEW_SIZES)}, got {shape!r}")
    obstacles = data.get("obstacles", [])
    if len(obstacles) >= MAX_OBSTACLES:
        raise RegraspError(f"the task has {len(obstacles)} obstacles, the most allowed")
    taken = {o.get("name") for o in obstacles}
    name = next(f"{shape}_{n}" for n in range(1, len(taken) + 2) if f"{shape}_{n}" not in taken)
    size = NEW_SIZES[shape]
    x, y, z = _finite(xyz, 3, "the new obstacle's position")
    data = copy.deepcopy(data)
    data.setdefault("obstacles", []).append({"name": name, "shape": shape, "size": list(size),
                                             "xyz": _round([x, y, z + size[-1] / 2]),
                                             "color": list(NEW_COLOR)})
    return data, name


def without_obstacle(data: TaskData, name: str) -> TaskData:
    """The task with obstacle `name` removed."""
    data = copy.deepcopy(data)
    del data["obstacles"][_index(data, name)]
    return data

