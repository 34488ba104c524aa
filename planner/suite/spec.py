"""Suite files (TOML in assets/suites/): a base task, objects, placement regions, a task count and seeds.

```toml
name = "default"
task = "default"      # the base task (scene, robot, start and goal configurations): a name in assets/tasks/ or a file
tasks = 60            # how many tasks to generate
seed = 0              # the generation seed: the same suite and seed give the same tasks
plan_seed = 0         # every task's session seed (one seed for all: they share the cached grasp lists and roadmap)
attempts = 30         # placements sampled for a task before its region is declared unable to yield a valid task
task_cpus = 1         # CPUs each task may use (its grasp search, transits...): a suite runs --workers tasks at once
task_timeout = 1200   # seconds a task may run before it is recorded as failed at stage "timeout"

[params.pick_grasps]  # step parameters every task runs with (as `--set pick_grasps.positions=20`); optional
positions = 20

[[objects]]           # the statuette, a mesh file (beside the suite or in assets/objects/, with scale and up), or a shape
name = "box_long"
shape = "box"         # one of planner/model/shapes.py's SHAPES, with its parameters
size = [0.22, 0.06, 0.07]

[[initial_regions]]   # where objects start (and [[final_regions]]: where they go): a box on the support, a yaw range
name = "right"
x = [0.42, 0.55]
y = [-0.88, -0.74]
z = 0.72              # the support's top: the object stands on it
yaw = [-3.14, 3.14]
```
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from planner.core.bounds import SEED
from planner.core.errors import InputError, RegraspError
from planner.core.paths import ASSETS, named_file
from planner.core.tomlread import Table, load_toml
from planner.model.object_mesh import UP_AXES, MeshOptions
from planner.model.shapes import SHAPES, generate, obj_text
from planner.model.task import BUILTIN_OBJECTS, MAX_COORDINATE, find_task
from planner.pipeline import step_named

SUITES_DIR = ASSETS / "suites"
NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]{0,39}")  # object and region names become file names and report labels
MAX_TASKS = 100_000
MAX_ATTEMPTS = 1000
MAX_TASK_CPUS = 256
MAX_TASK_TIMEOUT = 7 * 24 * 3600  # s


@dataclass(frozen=True)
class SuiteObject:
    """An object of the suite: its name, and the bytes of the mesh file its tasks name (or a built-in object's name)."""

    name: str
    builtin: str  # "statuette", or empty for a file
    file_name: str  # the mesh file written beside the generated tasks (empty for a built-in)
    data: bytes
    options: MeshOptions
    description: str  # what the object is, for the report


@dataclass(frozen=True)
class Region:
    """A box on the support where placements are sampled (x, y ranges, the support's top z) and a yaw range (rad)."""

    name: str
    field: str  # where it is in the suite file, for errors
    x: tuple[float, float]
    y: tuple[float, float]
    z: float
    yaw: tuple[float, float]

    def sample(self, rng: np.random.Generator) -> tuple[float, float, float]:
        """x, y and yaw drawn uniformly in the region."""
        return float(rng.uniform(*self.x)), float(rng.uniform(*self.y)), float(rng.uniform(*self.yaw))


@dataclass(frozen=True)
class SuiteSpec:
    """A loaded suite file."""

    source: Path
    text: str  # the file's text: a resumed suite must be the one it started with
    name: str
    base_task: Path
    tasks: int
    seed: int
    plan_seed: int
    attempts: int
    task_cpus: int
    task_timeout: float  # s
    params: dict[str, dict[str, Any]]  # step name -> parameter values (checked), for every task
    handover: bool
    objects: tuple[SuiteObject, ...]
    initial_regions: tuple[Region, ...]
    final_regions: tuple[Region, ...]


def find_suite(text: str | Path) -> Path:
    """The suite file `text` names: an existing file, else a name in assets/suites/ (see `named_file`)."""
    return named_file(text, SUITES_DIR, "suite")


def _name(tab: Table, seen: set[str]) -> str:
    name = tab.str("name")
    if not NAME.fullmatch(name):
        raise tab.error("name", f"expected letters, digits, '-' or '_' (at most 40, starting with a letter or digit), got {name!r}")
    if name in seen:
        raise tab.error("name", f"'{name}' is used twice; names must be unique")
    seen.add(name)
    return name


def _int(tab: Table, key: str, default: int, low: int, high: int) -> int:
    value = tab.data.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise tab.error(key, f"expected an integer from {low} to {high}, got {value!r}")
    return value


def _timeout(tab: Table) -> float:
    value = tab.data.get("task_timeout", 1200)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value <= MAX_TASK_TIMEOUT:
        raise tab.error("task_timeout", f"expected seconds, more than 0 and at most {MAX_TASK_TIMEOUT}, got {value!r}")
    return float(value)


def _params(root: Table) -> dict[str, dict[str, Any]]:
    """The suite's step parameters, each checked as `--set` checks it."""
    tables = root.data.get("params", {})
    if not isinstance(tables, dict) or not all(isinstance(v, dict) for v in tables.values()):
        raise root.error("params", "expected tables of step parameters, e.g. [params.pick_grasps] positions = 20")
    out: dict[str, dict[str, Any]] = {}
    for name, values in tables.items():
        try:
            step = step_named(name)
            step.make_params(values)
        except RegraspError as exc:
            raise root.error(f"params.{name}", str(exc)) from exc
        out[step.name] = dict(values)
    return out


def _range(tab: Table, key: str, limit: float, default: Any = None) -> tuple[float, float]:
    lo, hi = tab.vector(key, 2, default=default).tolist()
    if not -limit <= lo <= hi <= limit:
        raise tab.error(key, f"expected [low, high] with low <= high, within [-{limit:g}, {limit:g}], got {[lo, hi]}")
    return lo, hi


def _region(tab: Table, seen: set[str]) -> Region:
    tab.check_keys({"name", "x", "y", "z", "yaw"})
    name = _name(tab, seen)
    z = tab.float("z")
    if abs(z) > MAX_COORDINATE:
        raise tab.error("z", f"expected the support's height within {MAX_COORDINATE:g} m (metres), got {z}")
    return Region(name, tab.path, _range(tab, "x", MAX_COORDINATE), _range(tab, "y", MAX_COORDINATE), z,
                  _range(tab, "yaw", np.pi + 1e-6, default=[-np.pi, np.pi]))


def _shape_params(tab: Table, shape: str) -> dict[str, float | tuple[float, ...]]:
    spec = SHAPES[shape]
    tab.check_keys({"name", "shape", *spec.params})
    params: dict[str, float | tuple[float, ...]] = {}
    for key, n in spec.params.items():
        if key not in tab.data and key in spec.defaults:
            continue
        if n == 1:
            params[key] = tab.float(key, positive=True)
        else:
            values = tab.vector(key, n)
            if values.min() <= 0 or values.max() > 1.0:
                raise tab.error(key, f"expected {n} positive lengths up to 1 m (metres), got {values.tolist()}")
            params[key] = tuple(values.tolist())
        if n == 1 and params[key] > 1.0:
            raise tab.error(key, f"expected a length up to 1 m (metres), got {params[key]}")
    return params


def _object(tab: Table, seen: set[str], base: Path) -> SuiteObject:
    name = _name(tab, seen)
    if tab.has("shape") == tab.has("mesh"):
        raise tab.error(None, "expected either `shape` (a generated object) or `mesh` (the statuette or a mesh file)")
    if tab.has("shape"):
        shape = tab.str("shape")
        if shape not in SHAPES:
            raise tab.error("shape", f"expected one of {', '.join(SHAPES)}, got '{shape}'")
        params = _shape_params(tab, shape)
        try:
            mesh = generate(shape, params)
        except RegraspError as exc:
            raise tab.error("shape", str(exc)) from exc
        described = ", ".join(f"{k} {v}" for k, v in params.items())
        return SuiteObject(name, "", f"{name}.obj", obj_text(mesh).encode(), MeshOptions(), f"{shape} ({described or 'defaults'})")
    tab.check_keys({"name", "mesh", "scale", "up"})
    value = tab.str("mesh")
    options = MeshOptions(tab.float("scale", default=1.0, positive=True), tab.str("up", default="z"))
    if options.up not in UP_AXES:
        raise tab.error("up", f"expected the mesh file's up axis, one of {', '.join(UP_AXES)}, got '{options.up}'")
    if value in BUILTIN_OBJECTS:
        if options != MeshOptions():
            raise tab.error("mesh", f"the built-in '{value}' takes no scale or up")
        return SuiteObject(name, value, "", b"", options, f"the built-in {value}")
    for candidate in (base / value, ASSETS / "objects" / value):
        if candidate.is_file():
            return SuiteObject(name, "", f"{name}{candidate.suffix.lower()}", candidate.read_bytes(), options, f"mesh {value}")
    raise tab.error("mesh", f"file '{value}' not found (looked beside the suite file and in {ASSETS / 'objects'}); "
                            f"or a built-in object: {', '.join(BUILTIN_OBJECTS)}")


def load_suite(path: str | Path) -> SuiteSpec:
    """Read and check a suite file (a bare name is looked up in assets/suites/); errors name the file and the field."""
    path = find_suite(path)
    data = load_toml(path)
    root = Table(data, path)
    root.check_keys({"name", "description", "task", "tasks", "seed", "plan_seed", "attempts", "task_cpus", "task_timeout", "params",
                    "handover",
                    "objects",
                     "initial_regions", "final_regions"})
    task_value = root.str("task")
    beside = path.parent / task_value
    try:
        base_task = beside if beside.is_file() else find_task(task_value)
    except InputError as exc:
        raise root.error("task", exc.detail) from exc
    objects_seen: set[str] = set()
    objects = tuple(_object(t, objects_seen, path.parent) for t in root.tables("objects"))
    regions_seen: set[str] = set()
    regions = {key: tuple(_region(t, regions_seen) for t in root.tables(key)) for key in ("initial_regions", "final_regions")}
    for key, found in (("objects", objects), *regions.items()):
        if not found:
            raise root.error(key, "expected at least one")
    return SuiteSpec(path, path.read_text(), root.str("name"), base_task.resolve(), _int(root, "tasks", 10, 1, MAX_TASKS),
                     _int(root, "seed", 0, 0, 2**63 - 1), _int(root, "plan_seed", 0, SEED.low, SEED.high),
                     _int(root, "attempts", 30, 1, MAX_ATTEMPTS), _int(root, "task_cpus", 1, 1, MAX_TASK_CPUS),
                     _timeout(root), _params(root), root.bool("handover", default=True), objects,
                     regions["initial_regions"], regions["final_regions"])
