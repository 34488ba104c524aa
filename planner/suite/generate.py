"""Deterministic generation of a suite's tasks: each one a task file that `regrasp check` accepts.

Task i draws from its own generator (`default_rng([seed, i])`): its object is the suite's objects in turn, its regions
and placements are drawn. A placement is kept once it is valid on its own (the object penetrates nothing, the robot's
start or end configuration is free of it, some arm reaches it); the other is drawn again until the whole task passes
`check`. A region that yields no valid task in `attempts` draws is an error naming the region.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from planner.check import check_task, object_collisions
from planner.collision.checker import CollisionModel, build_collision_model
from planner.core.errors import InputError
from planner.core.forked import forked_map
from planner.core.paths import ASSETS, plain_name
from planner.core.results import atomic_write_bytes, atomic_write_text, writing
from planner.core.session import cached_spec_file
from planner.core.toml_text import toml_text
from planner.core.tomlread import load_toml
from planner.model.geometry import pose
from planner.model.object_mesh import MeshOptions, load_object_mesh
from planner.model.task import BUILTIN_OBJECTS, Scene, load_task, scene_from_dict
from planner.suite.spec import Region, SuiteObject, SuiteSpec

PLACEMENTS = ("initial", "final")


@dataclass(frozen=True)
class GeneratedTask:
    """One task of a suite: its id (also its task file's and session's name), object, regions and placements (x, y, z, yaw)."""

    id: str
    index: int
    object: str
    initial_region: str
    final_region: str
    initial: tuple[float, float, float, float]
    final: tuple[float, float, float, float]
    files: tuple[str, ...]  # the files in the tasks folder it needs: its task file first, then the robot spec and meshes

    def to_json(self) -> dict[str, Any]:
        return {"id": self.id, "index": self.index, "object": self.object, "initial_region": self.initial_region,
                "final_region": self.final_region, "initial": list(self.initial), "final": list(self.final), "files": list(self.files)}


@dataclass(frozen=True)
class RegionFailure:
    """No valid task in the attempts: the regions whose placements never became valid, and the last problem."""

    regions: tuple[Region, ...]
    problem: str


@dataclass(frozen=True)
class Base:
    """What every task shares: the base task's data (its files renamed into the tasks folder), the robot spec, the meshes."""

    data: dict[str, Any]
    robot_spec: Path  # the spec, content-addressed in the user cache (one robot loaded per process for every task)
    files: dict[str, bytes]  # name -> bytes of the shared files written beside the tasks (the robot spec, obstacle meshes)


def task_id(spec: SuiteSpec, index: int) -> str:
    """'0007-box_long': the task's number (from 1, zero-padded) and its object."""
    width = max(4, len(str(spec.tasks)))
    return f"{index + 1:0{width}d}-{spec.objects[index % len(spec.objects)].name}"


def _base(spec: SuiteSpec) -> Base:
    """The base task with its robot spec and mesh obstacles as plain names of files beside the generated tasks."""
    scene = load_task(spec.base_task)
    data = copy.deepcopy(scene.task)
    robot = scene.robot.spec
    files = {robot.source.name: robot.text().encode()}
    data["robot"] = robot.source.name
    for k, obstacle in enumerate(data.get("obstacles", [])):
        if "mesh" in obstacle and obstacle["mesh"] not in BUILTIN_OBJECTS:
            found = next(p for p in (spec.base_task.parent / obstacle["mesh"], ASSETS / "objects" / obstacle["mesh"]) if p.is_file())
            obstacle["mesh"] = f"obstacle{k}-{found.name}"
            files[obstacle["mesh"]] = found.read_bytes()
    return Base(data, cached_spec_file(robot.text(), robot.source.name, spec.base_task), files)


def _object_mesh(obj: SuiteObject, folder: Path) -> trimesh.Trimesh:
    """The object as its tasks load it (from the file written in the tasks folder), for its height above the support."""
    return load_object_mesh(BUILTIN_OBJECTS[obj.builtin] if obj.builtin else folder / obj.file_name, obj.options)


def _task_data(spec: SuiteSpec, base: Base, obj: SuiteObject, index: int, placements: dict[str, tuple[float, ...]]) -> dict[str, Any]:
    data = copy.deepcopy(base.data)
    data["name"] = task_id(spec, index)
    data["description"] = f"suite {spec.name}, task {index + 1}: the {obj.name} from region to region"
    data["handover"] = spec.handover
    mesh: dict[str, Any] = {"mesh": obj.builtin or obj.file_name}
    if obj.options != MeshOptions():
        mesh |= {"scale": obj.options.scale, "up": obj.options.up}
    data["object"] = {**mesh, **{k: {"xyz": list(v[:3]), "rpy": [0.0, 0.0, v[3]]} for k, v in placements.items()}}
    return data


class Generator:
    """Draws a suite's tasks in a tasks folder where the shared files are written (a forked worker draws some of them)."""

    def __init__(self, spec: SuiteSpec, folder: Path):
        self.spec, self.folder = spec, folder
        self.base = _base(spec)
        with writing(folder):
            folder.mkdir(parents=True, exist_ok=True)
        for name, data in self.base.files.items():
            atomic_write_bytes(folder / name, data)
        for obj in spec.objects:
            if obj.file_name:
                atomic_write_bytes(folder / obj.file_name, obj.data)
        self.lift = {obj.name: -float(_object_mesh(obj, folder).bounds[0][2]) for obj in spec.objects}
        first = self._scene(0, {k: (0.0, 0.0, 0.0, 0.0) for k in PLACEMENTS})
        self.cm: CollisionModel = build_collision_model(first.robot, first.environment)

    def _scene(self, index: int, placements: dict[str, tuple[float, ...]], meshes: dict | None = None) -> Scene:
        obj = self.spec.objects[index % len(self.spec.objects)]
        data = _task_data(self.spec, self.base, obj, index, placements)
        return scene_from_dict(data, self.folder / f"{task_id(self.spec, index)}.toml", self.base.robot_spec, meshes)

    def draw(self, index: int) -> GeneratedTask | RegionFailure:
        """Task `index`, or the regions that could not yield it."""
        spec = self.spec
        obj = spec.objects[index % len(spec.objects)]
        rng = np.random.default_rng([spec.seed, index])
        regions = {"initial": spec.initial_regions[int(rng.integers(len(spec.initial_regions)))],
                   "final": spec.final_regions[int(rng.integers(len(spec.final_regions)))]}
        placed: dict[str, tuple[float, float, float, float]] = {}
        valid = {k: False for k in PLACEMENTS}
        meshes: dict | None = None
        problem = ""
        for _ in range(spec.attempts):
            for k in PLACEMENTS:
                if not valid[k]:
                    x, y, yaw = regions[k].sample(rng)
                    placed[k] = (round(x, 4), round(y, 4), round(regions[k].z + self.lift[obj.name], 4), round(yaw, 4))
            scene = self._scene(index, placed, meshes)
            meshes = scene.meshes
            poses = {k: pose(placed[k][:3], [0.0, 0.0, placed[k][3]]) for k in PLACEMENTS}
            hits = {k: object_collisions(scene, poses[k]) for k in PLACEMENTS}
            if any(hits.values()):
                problem = "; ".join(f"the {k} placement penetrates {', '.join(h)}" for k, h in hits.items() if h)
                valid = {k: valid[k] or not hits[k] for k in PLACEMENTS}
                continue
            report = check_task(scene, self.cm)
            if report.ok:
                return GeneratedTask(task_id(spec, index), index, obj.name, regions["initial"].name, regions["final"].name,
                                     placed["initial"], placed["final"], (f"{task_id(spec, index)}.toml", *self._files(obj)))
            problem = "; ".join(report.problems)
            alone = {k: not report.config_collisions[k] and any(r.reachable for r in report.reach[k].values()) for k in PLACEMENTS}
            valid = alone if not all(alone.values()) else {k: False for k in PLACEMENTS}
        return RegionFailure(tuple(regions[k] for k in PLACEMENTS if not valid[k]), problem)

    def _files(self, obj: SuiteObject) -> tuple[str, ...]:
        return (*self.base.files, *((obj.file_name,) if obj.file_name else ()))

    def write(self, task: GeneratedTask) -> None:
        """Write a drawn task's file."""
        data = _task_data(self.spec, self.base, self.spec.objects[task.index % len(self.spec.objects)], task.index,
                          {"initial": task.initial, "final": task.final})
        atomic_write_text(self.folder / task.files[0], toml_text(data))


def generate_tasks(spec: SuiteSpec, folder: Path, workers: int = 1) -> list[GeneratedTask]:
    """Every task of the suite, drawn over `workers` forked processes (the same tasks whatever their number), written in `folder`."""
    generator = Generator(spec, folder)
    drawn = forked_map(generator.draw, range(spec.tasks), workers)
    for index, task in enumerate(drawn):
        if isinstance(task, RegionFailure):
            names = " and ".join(f"'{r.name}'" for r in task.regions) or "the regions drawn"
            field = task.regions[0].field if task.regions else None
            raise InputError(spec.source, field, f"region {names} yielded no valid task for task {index + 1} in {spec.attempts} "
                                                 f"placements drawn (last problem: {task.problem})")
        generator.write(task)
    return drawn


def load_generated(folder: Path, spec: SuiteSpec, tasks: list[dict[str, Any]]) -> list[GeneratedTask]:
    """The tasks a suite folder's manifest lists, each checked to name its task file (what a resumed suite runs)."""
    manifest = folder.parent / "suite-run.json"
    out = []
    for i, t in enumerate(tasks):
        files = tuple(plain_name(f, manifest, f"tasks[{i}].files[{k}]") for k, f in enumerate(t["files"]))
        task = GeneratedTask(t["id"], int(t["index"]), t["object"], t["initial_region"], t["final_region"],
                             tuple(t["initial"]), tuple(t["final"]), files)
        if task.id != task_id(spec, i) or task.index != i or not files or not (folder / files[0]).is_file():
            raise InputError(manifest, f"tasks[{i}]", f"expected task {task_id(spec, i)} with its file in {folder}")
        load_toml(folder / task.files[0])
        out.append(task)
    return out
