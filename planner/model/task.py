"""Task files (TOML in assets/tasks/): robot, obstacles, object and its two placements, start and goal.

A `Scene` is everything a task names, loaded and checked: the composed robot, the obstacles, the
object mesh, its initial/final poses and the robot's initial/final configurations.
"""
from __future__ import annotations

import copy
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from planner.core.errors import InputError
from planner.core.paths import ASSETS, TASKS_DIR, named_file
from planner.core.results import frozen
from planner.core.tomlread import Table, load_toml
from planner.model.environment import SHAPES, Environment, Obstacle
from planner.model.geometry import pose
from planner.model.object_mesh import (
    OBJECT_LIMITS,
    OBSTACLE_LIMITS,
    UP_AXES,
    MeshOptions,
    SizeLimits,
    checked_mesh,
    load_mesh,
)
from planner.model.robot import Robot, load_robot

ROBOTS_DIR = ASSETS / "robots"  # the robot specs the project ships; a task names one by its file name
OBJECTS_DIR = ASSETS / "objects"  # where a task's mesh is looked for when it is not beside the task file
BUILTIN_OBJECTS = {"statuette": OBJECTS_DIR / "statuette.obj"}
MAX_OBSTACLES = 500  # more makes every collision check slow (check would run for minutes); merge small parts into meshes
MAX_COORDINATE = 100.0  # m: a placement farther from the robot than this is a typo or a unit error
MAX_ANGLE = 2 * np.pi + 1e-6  # rad: larger roll/pitch/yaw values are degrees given as radians
MAX_DESCRIPTION = 2000  # characters: a sentence or a paragraph about the task
MAX_SCALE = 1e4  # a mesh scale outside [1/MAX_SCALE, MAX_SCALE] is not a unit conversion


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
    handover: bool = False  # the task asks for a regrasp even when one arm reaches both placements


def find_file(value: str, base: Path, search: Path) -> Path | None:
    """The file or folder a task's field names: `value` beside the task file (in `base`), else in `search`; None if neither."""
    return next((c.resolve() for c in (base / value, search / value) if c.exists()), None)


def _path(tab: Table, key: str, base: Path, search: Path) -> Path:
    """The file a field names, beside the task file or in `search`; a directory is refused by name."""
    value = tab.str(key)
    found = find_file(value, base, search)
    if found is not None and found.is_dir():
        raise tab.error(key, f"'{value}' is a directory ({found}); expected a file")
    if found is None or not found.is_file():
        raise tab.error(key, f"file '{value}' not found (looked beside the task file and in {search})")
    return found


def _pose(tab: Table) -> np.ndarray:
    """The pose of fields `xyz` (m, within MAX_COORDINATE of the robot) and `rpy` (rad, default 0, at most a turn)."""
    xyz = tab.vector("xyz", 3)
    if np.max(np.abs(xyz)) > MAX_COORDINATE:
        raise tab.error("xyz", f"expected coordinates within {MAX_COORDINATE:g} m of the robot (metres), got {xyz.tolist()}")
    rpy = tab.vector("rpy", 3, default=[0.0, 0.0, 0.0])
    if np.max(np.abs(rpy)) > MAX_ANGLE:
        raise tab.error("rpy", f"expected angles in radians within [-2 pi, 2 pi], got {rpy.tolist()} (degrees given as radians?)")
    return pose(xyz, rpy)


def _placement(tab: Table) -> np.ndarray:
    tab.check_keys({"xyz", "rpy"})
    return _pose(tab)


def _mesh_options(tab: Table) -> MeshOptions:
    """The `scale` and `up` fields beside a mesh field."""
    scale = tab.float("scale", default=1.0, positive=True)
    if not 1 / MAX_SCALE <= scale <= MAX_SCALE:
        raise tab.error("scale", f"expected a unit conversion factor between {1 / MAX_SCALE:g} and {MAX_SCALE:g} "
                                 f"(e.g. 0.001 for a mesh in millimetres), got {scale:g}")
    up = tab.str("up", default="z")
    if up not in UP_AXES:
        raise tab.error("up", f"expected the mesh file's up axis, one of {', '.join(UP_AXES)} (glTF files are y-up), got '{up}'")
    return MeshOptions(scale, up)


def mesh_key(value: str, options: MeshOptions) -> str:
    """The one name a mesh is known by in a scene's `meshes` (and a session's embedded meshes): the task's value, with its
    scale and up axis when they are not the defaults (one file placed two ways is two meshes)."""
    return value if options == MeshOptions() else f"{value} (scale {options.scale:g}, up {options.up})"


def _mesh(tab: Table, key: str, base: Path, meshes: dict[str, trimesh.Trimesh], limits: SizeLimits,
          embedded: str | None) -> trimesh.Trimesh:
    """The mesh a field names, scaled and turned upright by the table's options: from `meshes` when it holds it, else
    from its file; a fault in the file is reported at the task's field, naming the mesh file. A replayed session's
    meshes (`embedded` names the file holding them) are only looked up, never read from the disk, and pass the checks
    a mesh file passes."""
    value = tab.str(key)
    name = mesh_key(value, _mesh_options(tab))
    if embedded is not None:
        if name not in meshes:
            raise tab.error(key, f"the mesh {name!r} is not embedded in the session's {embedded}; a session reads no mesh file")
        try:
            checked_mesh(meshes[name], f"{embedded} ({name!r})", limits, None)
        except InputError as exc:
            raise tab.error(key, f"the embedded {limits.what} mesh in {exc}") from exc
    elif name not in meshes:
        path = BUILTIN_OBJECTS.get(value) or _path(tab, key, base, OBJECTS_DIR)
        try:
            meshes[name] = load_mesh(path, limits, _mesh_options(tab))
        except InputError as exc:
            raise tab.error(key, f"the {limits.what} mesh {exc}") from exc
    return meshes[name]


def _color(tab: Table) -> tuple[int, int, int]:
    """An RGB colour: three integers 0-255."""
    color = tab.vector("color", 3, default=[170, 160, 150])
    if np.any(color != np.round(color)) or np.any(color < 0) or np.any(color > 255):
        raise tab.error("color", f"expected three integers from 0 to 255 (red, green, blue), got {color.tolist()}")
    return tuple(int(c) for c in color)


def _obstacle(tab: Table, base: Path, meshes: dict[str, trimesh.Trimesh], embedded: str | None) -> Obstacle:
    shape = tab.str("shape")
    if shape not in SHAPES:
        raise tab.error("shape", f"expected one of {', '.join(SHAPES)}, got '{shape}'")
    mesh = None
    size: tuple[float, ...] = ()
    if shape == "mesh":
        tab.str("mesh")  # a missing mesh is named before the keys a primitive would have
        tab.check_keys({"name", "shape", "xyz", "rpy", "color", "mesh", "scale", "up"})
        mesh = _mesh(tab, "mesh", base, meshes, OBSTACLE_LIMITS, embedded)
    else:
        tab.check_keys({"name", "shape", "size", "xyz", "rpy", "color"})
        size = tuple(tab.vector("size", SHAPES[shape]).tolist())
        if min(size) <= 0 or max(size) > OBSTACLE_LIMITS.high:
            raise tab.error("size", f"expected positive dimensions up to {OBSTACLE_LIMITS.high:g} m (metres), got {list(size)}")
    return Obstacle(tab.str("name"), shape, size, _pose(tab), _color(tab), mesh)


def _description(root: Table) -> str:
    """The task's description: a string of at most MAX_DESCRIPTION characters (empty when absent)."""
    value = root.data.get("description", "")
    if not isinstance(value, str) or len(value) > MAX_DESCRIPTION:
        what = f"{len(value):,} characters" if isinstance(value, str) else type(value).__name__
        raise root.error("description", f"expected a text of at most {MAX_DESCRIPTION:,} characters, got {what}")
    return value


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
                    meshes: dict[str, trimesh.Trimesh] | None = None, field_prefix: str = "",
                    embedded: str | None = None) -> Scene:
    """Build a Scene from parsed task data (`meshes`: meshes already loaded, by `mesh_key`).

    A replayed session passes the robot spec and the meshes it embedded (`robot_path`, `meshes`, and `embedded`, the
    name of the file holding them: no other mesh is read), and `field_prefix` so errors name the field inside the
    session file.
    """
    root = Table(data, source, field_prefix)
    root.check_keys({"name", "description", "robot", "object", "obstacles", "robot_initial", "robot_final", "handover"})
    base = source.parent
    robot = load_robot(robot_path or _path(root, "robot", base, ROBOTS_DIR))
    meshes = dict(meshes or {})
    obj = root.table("object")
    obj.check_keys({"mesh", "initial", "final", "scale", "up"})
    mesh_name = obj.str("mesh")
    object_mesh = _mesh(obj, "mesh", base, meshes, OBJECT_LIMITS, embedded)
    obstacle_tables = root.tables("obstacles") if root.has("obstacles") else []
    if len(obstacle_tables) > MAX_OBSTACLES:
        raise root.error("obstacles", f"{len(obstacle_tables):,} obstacles, more than the {MAX_OBSTACLES} allowed "
                                      "(every collision check tests each one); merge small parts into mesh obstacles")
    obstacles = tuple(_obstacle(t, base, meshes, embedded) for t in obstacle_tables)
    names = [o.name for o in obstacles]
    if len(set(names)) != len(names):
        raise root.error("obstacles", "obstacle names must be unique")
    return Scene(
        source=source,
        name=root.str("name"),
        description=_description(root),
        task=copy.deepcopy(data),
        robot=robot,
        environment=obstacles,
        object_name=mesh_name,
        object_mesh=object_mesh,
        object_initial=frozen(_placement(obj.table("initial"))),
        object_final=frozen(_placement(obj.table("final"))),
        q_initial=frozen(_configuration(root.table("robot_initial", default={}), robot)),
        q_final=frozen(_configuration(root.table("robot_final", default={}), robot)),
        meshes=meshes,
        handover=root.bool("handover", default=False),
    )


def find_task(text: str | Path) -> Path:
    """The task file `text` names: an existing file, else a name in assets/tasks/ (see `named_file`)."""
    return named_file(text, TASKS_DIR, "task")


def task_reference(source: Path, folder: Path) -> str:
    """How a session in `folder` records the task it came from: its name in assets/tasks/, else its path relative to the folder."""
    source = source.resolve()
    if source.parent == TASKS_DIR.resolve():
        return source.stem
    return os.path.relpath(source, folder.resolve())


def load_task(path: str | Path) -> Scene:
    """Read a task TOML file and build its Scene; a bare name is looked up in assets/tasks/ (see `find_task`)."""
    path = find_task(path)
    return scene_from_dict(load_toml(path), path.resolve())
