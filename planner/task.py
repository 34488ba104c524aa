"""Task files (TOML in assets/tasks/): robot, obstacles, object and its two placements, start and goal.

A `Scene` is everything a task names, loaded and checked: the composed robot, the obstacles, the
object mesh, its initial/final poses and the robot's initial/final configurations.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from .environment import SHAPES, Environment, Obstacle
from .errors import InputError
from .geometry import pose
from .object_mesh import load_object_mesh
from .paths import ASSETS
from .robot import Robot, load_robot
from .tomlread import Table, load_toml

BUILTIN_OBJECTS = {"statuette": ASSETS / "objects" / "statuette.obj"}


@dataclass(frozen=True, eq=False)
class Scene:
    """A loaded task. `task` keeps the TOML data, so a session can embed the task in full."""

    source: Path
    name: str
    description: str
    task: dict[str, Any] = field(repr=False)
    robot: Robot = field(repr=False)
    environment: Environment
    object_name: str
    object_mesh: trimesh.Trimesh = field(repr=False)
    object_initial: np.ndarray
    object_final: np.ndarray
    q_initial: np.ndarray
    q_final: np.ndarray

    def object_at(self, T: np.ndarray) -> trimesh.Trimesh:
        """The object mesh placed at a world pose."""
        return self.object_mesh.copy().apply_transform(T)


def _path(tab: Table, key: str, base: Path, search: Path) -> Path:
    value = tab.str(key)
    for candidate in (base / value, search / value):
        if candidate.is_file():
            return candidate.resolve()
    raise tab.error(key, f"file '{value}' not found (looked beside the task file and in {search})")


def _placement(tab: Table) -> np.ndarray:
    tab.check_keys({"xyz", "rpy"})
    return pose(tab.vector("xyz", 3), tab.vector("rpy", 3, default=[0.0, 0.0, 0.0]))


def _obstacle(tab: Table, base: Path) -> Obstacle:
    tab.check_keys({"name", "shape", "size", "xyz", "rpy", "color", "mesh"})
    shape = tab.str("shape")
    if shape not in SHAPES:
        raise tab.error("shape", f"expected one of {', '.join(SHAPES)}, got '{shape}'")
    mesh = None
    size: tuple[float, ...] = ()
    if shape == "mesh":
        mesh = load_object_mesh(_path(tab, "mesh", base, ASSETS / "objects"))
    else:
        size = tuple(tab.vector("size", SHAPES[shape]).tolist())
        if min(size) <= 0:
            raise tab.error("size", "expected positive dimensions (metres)")
    color = tab.vector("color", 3, default=[170, 160, 150])
    return Obstacle(tab.str("name"), shape, size, pose(tab.vector("xyz", 3), tab.vector("rpy", 3, default=[0.0, 0.0, 0.0])),
                    tuple(int(c) for c in color), mesh)


def _configuration(tab: Table, robot: Robot) -> np.ndarray:
    """'rest', optionally with joints overridden by name; values are checked against the limits."""
    tab.check_keys({"named", "joints"})
    named = tab.str("named", default="rest")
    if named != "rest":
        raise tab.error("named", f"unknown configuration '{named}' (known: rest)")
    joints = tab.number_map("joints", default={})
    names = robot.joint_names()
    for name, value in joints.items():
        if name not in names:
            raise tab.error(f"joints.{name}", f"the robot has no joint '{name}'")
        i = names.index(name)
        if not robot.lower[i] - 1e-9 <= value <= robot.upper[i] + 1e-9:
            raise tab.error(f"joints.{name}", f"{value} is outside the joint limits [{robot.lower[i]:.3f}, {robot.upper[i]:.3f}]")
    return robot.configuration(joints)


def scene_from_dict(data: dict[str, Any], source: Path) -> Scene:
    """Build a Scene from parsed task data (also used to replay the task embedded in a session)."""
    root = Table(data, source)
    root.check_keys({"name", "description", "robot", "object", "obstacles", "robot_initial", "robot_final"})
    base = source.parent
    robot_path = _path(root, "robot", base, ASSETS / "robots")
    robot = load_robot(robot_path)
    obj = root.table("object")
    obj.check_keys({"mesh", "initial", "final"})
    mesh_name = obj.str("mesh")
    mesh_path = BUILTIN_OBJECTS.get(mesh_name) or _path(obj, "mesh", base, ASSETS / "objects")
    obstacles = tuple(_obstacle(t, base) for t in root.tables("obstacles")) if root.has("obstacles") else ()
    names = [o.name for o in obstacles]
    if len(set(names)) != len(names):
        raise root.error("obstacles", "obstacle names must be unique")
    return Scene(
        source=source,
        name=root.str("name"),
        description=data.get("description", ""),
        task=copy.deepcopy(data),
        robot=robot,
        environment=obstacles,
        object_name=mesh_name,
        object_mesh=load_object_mesh(mesh_path),
        object_initial=_placement(obj.table("initial")),
        object_final=_placement(obj.table("final")),
        q_initial=_configuration(root.table("robot_initial", default={}), robot),
        q_final=_configuration(root.table("robot_final", default={}), robot),
    )


def load_task(path: str | Path) -> Scene:
    """Read a task TOML file and build its Scene; a bare name is looked up in assets/tasks/."""
    path = Path(path)
    if not path.exists() and (ASSETS / "tasks" / path).exists():
        path = ASSETS / "tasks" / path
    if not path.exists() and (ASSETS / "tasks" / f"{path}.toml").exists():
        path = ASSETS / "tasks" / f"{path}.toml"
    return scene_from_dict(load_toml(path), path.resolve())
