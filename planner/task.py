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
    meshes: dict[str, trimesh.Trimesh] = field(repr=False, default_factory=dict)  # every mesh the task names, by its task value

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


def _mesh(tab: Table, key: str, base: Path, meshes: dict[str, trimesh.Trimesh]) -> trimesh.Trimesh:
    """The mesh a field names: from `meshes` when given (a replayed session), else from its file."""
    value = tab.str(key)
    if value not in meshes:
        meshes[value] = load_object_mesh(BUILTIN_OBJECTS.get(value) or _path(tab, key, base, ASSETS / "objects"))
    return meshes[value]


def _obstacle(tab: Table, base: Path, meshes: dict[str, trimesh.Trimesh]) -> Obstacle:
    tab.check_keys({"name", "shape", "size", "xyz", "rpy", "color", "mesh"})
    shape = tab.str("shape")
    if shape not in SHAPES:
        raise tab.error("shape", f"expected one of {', '.join(SHAPES)}, got '{shape}'")
    mesh = None
    size: tuple[float, ...] = ()
    if shape == "mesh":
        mesh = _mesh(tab, "mesh", base, meshes)
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


def scene_from_dict(data: dict[str, Any], source: Path, robot_path: Path | None = None,
                    meshes: dict[str, trimesh.Trimesh] | None = None, field_prefix: str = "") -> Scene:
    """Build a Scene from parsed task data.

    A replayed session passes the robot spec and the meshes it embedded (`robot_path`, `meshes`),
    and `field_prefix` so errors name the field inside the session file.
    """
    root = Table(data, source, field_prefix)
    root.check_keys({"name", "description", "robot", "object", "obstacles", "robot_initial", "robot_final"})
    base = source.parent
    robot = load_robot(robot_path or _path(root, "robot", base, ASSETS / "robots"))
    meshes = dict(meshes or {})
    obj = root.table("object")
    obj.check_keys({"mesh", "initial", "final"})
    mesh_name = obj.str("mesh")
    object_mesh = _mesh(obj, "mesh", base, meshes)
    obstacles = tuple(_obstacle(t, base, meshes) for t in root.tables("obstacles")) if root.has("obstacles") else ()
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
        object_mesh=object_mesh,
        object_initial=_placement(obj.table("initial")),
        object_final=_placement(obj.table("final")),
        q_initial=_configuration(root.table("robot_initial", default={}), robot),
        q_final=_configuration(root.table("robot_final", default={}), robot),
        meshes=meshes,
    )


def load_task(path: str | Path) -> Scene:
    """Read a task TOML file and build its Scene; a bare name is looked up in assets/tasks/."""
    path = Path(path)
    if not path.exists() and (ASSETS / "tasks" / path).exists():
        path = ASSETS / "tasks" / path
    if not path.exists() and (ASSETS / "tasks" / f"{path}.toml").exists():
        path = ASSETS / "tasks" / f"{path}.toml"
    return scene_from_dict(load_toml(path), path.resolve())
