"""Sessions: a folder holding a task, the results of the steps run on it, and how they were run.

`session.json` (written last, atomically) has `format_version`, `task` (the task data in full),
`robot_spec` (the spec's text), `seed`, `versions` and `steps`: in pipeline order, one
`{"name", "params", "seed", "seconds", "stats", "files"}` per finished step (and `stage_seconds`, the seconds of its
stages, and `"cached": true` when its result was loaded from the user cache, both when they apply). `task_meshes.npz`
holds every mesh the task names, so a replay needs no task file. `task_source` says where the task came from (a name
in assets/tasks/ or a path relative to the session): a note for people, never opened (old sessions hold absolute paths). Each step writes
`<step>.npz` + `<step>.json` (see `results.py`).
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import platform
import shutil
from importlib import metadata
from pathlib import Path
from typing import Any, NoReturn

import numpy as np
import trimesh

from planner import __version__
from planner.core.bounds import seed_problem
from planner.core.errors import InputError, RegraspError
from planner.core.npz import Budget, NpzFile, npz_bytes
from planner.core.paths import cache_dir, file_in, plain_name
from planner.core.results import (
    atomic_write_bytes,
    atomic_write_text,
    load_result,
    read_json_object,
    regular_file,
    save_result,
    writing,
)
from planner.core.steps import Step
from planner.model.object_mesh import MAX_FACES, check_face_count
from planner.model.robot import load_robot
from planner.model.task import MAX_OBSTACLES, Scene, scene_from_dict, task_reference
from planner.pipeline import PIPELINE, step_named

FORMAT_VERSION = 1
MANIFEST = "session.json"
MESHES = "task_meshes.npz"
STEP_KEYS = ("name", "params", "seed", "seconds", "stats", "files")
OPTIONAL_STEP_KEYS = ("stage_seconds", "cached")
MANIFEST_KEYS = ("format_version", "task", "robot_spec", "robot_spec_name", "seed", "versions", "steps")
# (step, need) pairs added after sessions were saved without the need: such a session still opens (its step's result
# was made without it); running the step again runs the need first
ADDED_NEEDS = {("motion", "placements")}
MAX_SPEC_CHARS = 1_000_000
MAX_KEY_CHARS = 1000  # an embedded mesh's key: the task's mesh value, its scale and up axis


def package_versions() -> dict[str, str]:
    """Versions of Python and of the packages a result depends on."""
    out = {"python": platform.python_version(), "regrasp": __version__}
    for name in ("numpy", "scipy", "pin", "coal", "trimesh", "python-fcl", "example-robot-data", "ompl", "viser"):
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            pass
    return out


def _save_meshes(folder: Path, meshes: dict[str, trimesh.Trimesh]) -> None:
    arrays = {}
    for i, (key, mesh) in enumerate(sorted(meshes.items())):
        arrays[f"{i}_key"] = np.array(key)
        arrays[f"{i}_vertices"] = np.asarray(mesh.vertices, dtype=np.float64)
        arrays[f"{i}_faces"] = np.asarray(mesh.faces, dtype=np.int64)
    atomic_write_bytes(folder / MESHES, npz_bytes(arrays))


def _load_meshes(folder: Path, budget: Budget) -> dict[str, trimesh.Trimesh]:
    """The embedded meshes, each checked before its data is read (a string key, finite (n, 3) float64 vertices, at most
    MAX_FACES (m, 3) integer faces indexing them); `task._mesh` checks each as a mesh file is checked when the task names it."""
    path = regular_file(folder / MESHES, "the session's embedded meshes are gone")
    out = {}
    with NpzFile(path, budget) as npz:
        n = len([k for k in npz.names() if k.endswith("_key")])
        if n > MAX_OBSTACLES + 1:
            _fail(path, None, f"holds {n:,} meshes; a task names at most {MAX_OBSTACLES + 1} (its object and its obstacles)")
        for i in range(n):
            npz.header(f"{i}_key", np.dtype("U"), (), max_bytes=4 * MAX_KEY_CHARS)
            npz.header(f"{i}_vertices", np.dtype(np.float64), ("n", 3), {}, lambda shape, i=i: _vertex_count(shape[0], path, i))
            npz.header(f"{i}_faces", np.dtype(np.int64), ("m", 3), {}, lambda shape, i=i: check_face_count(shape[0], path, f"{i}_faces"))
            key, vertices, faces = (npz.read(f"{i}_{part}") for part in ("key", "vertices", "faces"))
            if not np.isfinite(vertices).all():
                _fail(path, f"{i}_vertices", "expected finite coordinates, found NaN or infinite ones")
            if faces.size and (faces.min() < 0 or faces.max() >= len(vertices)):
                _fail(path, f"{i}_faces", f"expected (m, 3) integer indices below {len(vertices)}")
            out[str(key)] = trimesh.Trimesh(vertices, faces, process=False)
    return out


def _vertex_count(count: int, path: Path, i: int) -> None:
    """Refuse more vertices than MAX_FACES triangles can use (three each)."""
    if count > 3 * MAX_FACES:
        _fail(path, f"{i}_vertices", f"has {count:,} vertices, more than the {3 * MAX_FACES:,} allowed "
                                     f"(three for each of at most {MAX_FACES:,} triangles)")


def cached_spec_file(text: str, name: str, manifest: Path) -> Path:
    """The embedded robot spec written to the user cache (content-addressed), to load it from there."""
    folder = cache_dir() / "specs" / hashlib.sha256(text.encode()).hexdigest()[:16]
    path = file_in(folder, name, manifest, "robot_spec_name")
    with writing(folder):
        folder.mkdir(parents=True, exist_ok=True)
        if path.is_symlink() or not path.is_file() or path.read_text() != text:
            atomic_write_text(path, text)
    return path


def step_files(name: str) -> list[str]:
    """The files a step's result is saved in (what `save_result` writes)."""
    return [f"{name}.npz", f"{name}.json"]


def _fail(path: Path, field: str | None, message: str) -> NoReturn:
    raise InputError(path, field, message)


def typed(value: Any, kind: type | tuple[type, ...], path: Path, field: str, what: str) -> Any:
    """`value` if it is of `kind` (bools are not numbers here), else an InputError saying what was expected."""
    if isinstance(value, bool) and bool not in (kind if isinstance(kind, tuple) else (kind,)) or not isinstance(value, kind):
        _fail(path, field, f"expected {what}, got {type(value).__name__} {_short(value)}")
    return value


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _seed(value: Any, path: Path, field: str) -> int:
    typed(value, int, path, field, "an integer seed")
    if seed_problem(value):  # the range `--seed` checks too
        _fail(path, field, seed_problem(value))
    return value


def checked_seconds(value: Any, path: Path, field: str) -> float:
    typed(value, (int, float), path, field, "a number of seconds")
    if not math.isfinite(value) or value < 0:
        _fail(path, field, f"expected a finite number of seconds >= 0, got {value}")
    return value


def _finite_params(params: dict[str, Any], path: Path, field: str) -> None:
    for key, value in params.items():
        if isinstance(value, float) and not math.isfinite(value):
            _fail(path, f"{field}.{key}", f"expected a finite number, got {value}")


def _check_step(record: Any, index: int, done: list[str], path: Path) -> None:
    """One `steps[]` record: its keys, a known step after those it needs, and well-typed values."""
    field = f"steps[{index}]"
    typed(record, dict, path, field, f"an object with {', '.join(STEP_KEYS)}")
    for key in STEP_KEYS:
        if key not in record:
            _fail(path, f"{field}.{key}", "missing field")
    unknown = sorted(set(record) - set(STEP_KEYS) - set(OPTIONAL_STEP_KEYS))
    if unknown:
        _fail(path, f"{field}.{unknown[0]}", "unknown field")
    order = [s.name for s in PIPELINE]
    name = typed(record["name"], str, path, f"{field}.name", "a step name")
    if name not in order:
        _fail(path, f"{field}.name", f"no step {_short(name)} (steps: {', '.join(order)})")
    if name in done:
        _fail(path, f"{field}.name", f"step '{name}' is listed twice")
    if done and order.index(name) < order.index(done[-1]):
        _fail(path, f"{field}.name", f"step '{name}' is listed after '{done[-1]}': steps must be in pipeline order ({', '.join(order)})")
    step = step_named(name)
    for need in step.needs:
        if need not in done and (name, need) not in ADDED_NEEDS:
            _fail(path, f"{field}.name", f"step '{name}' needs '{need}', which is not listed before it")
    params = typed(record["params"], dict, path, f"{field}.params", "an object of parameters")
    _finite_params(params, path, f"{field}.params")  # first: it names the parameter's own field
    try:
        step.recorded_params(params)
    except RegraspError as exc:
        raise InputError(path, f"{field}.params", str(exc)) from exc
    _seed(record["seed"], path, f"{field}.seed")
    checked_seconds(record["seconds"], path, f"{field}.seconds")
    typed(record["stats"], dict, path, f"{field}.stats", "an object of statistics")
    files = typed(record["files"], list, path, f"{field}.files", "a list of file names")
    for k, f in enumerate(files):
        plain_name(f, path, f"{field}.files[{k}]")
    if files != step_files(name):
        _fail(path, f"{field}.files", f"expected {step_files(name)}, got {_short(files)}")
    if "cached" in record:
        typed(record["cached"], bool, path, f"{field}.cached", "true or false")
    if "stage_seconds" in record:
        for k, t in enumerate(typed(record["stage_seconds"], list, path, f"{field}.stage_seconds", "a list of seconds")):
            checked_seconds(t, path, f"{field}.stage_seconds[{k}]")


def check_manifest(manifest: dict[str, Any], path: Path) -> None:
    """Validate a whole manifest (types, names, order, finiteness) before anything touches the disk or the cache."""
    for key in MANIFEST_KEYS:
        if key not in manifest:
            _fail(path, key, "missing field")
    unknown = sorted(set(manifest) - set(MANIFEST_KEYS) - {"task_source"})
    if unknown:
        _fail(path, unknown[0], "unknown field")
    version = typed(manifest["format_version"], int, path, "format_version", "an integer format version")
    if version > FORMAT_VERSION:
        _fail(path, "format_version", f"format {version!r} was written by a newer regrasp; this one reads formats up to {FORMAT_VERSION}")
    if version < 1:
        _fail(path, "format_version", f"expected a format version from 1 to {FORMAT_VERSION}, got {version}")
    typed(manifest["task"], dict, path, "task", "the task as a JSON object")
    if "task_source" in manifest:
        typed(manifest["task_source"], str, path, "task_source", "the task's name or its path relative to the session, as a string")
    spec = typed(manifest["robot_spec"], str, path, "robot_spec", "the robot spec's text")
    if not spec.strip() or len(spec) > MAX_SPEC_CHARS:
        _fail(path, "robot_spec", f"expected the robot spec's text (1 to {MAX_SPEC_CHARS} characters), got {len(spec)} characters")
    plain_name(manifest["robot_spec_name"], path, "robot_spec_name")
    _seed(manifest["seed"], path, "seed")
    versions = typed(manifest["versions"], dict, path, "versions", "an object of package versions")
    for key, value in versions.items():
        typed(value, str, path, f"versions.{key}", "a version string")
    done: list[str] = []
    for i, record in enumerate(typed(manifest["steps"], list, path, "steps", "a list")):
        _check_step(record, i, done, path)
        done.append(record["name"])


class Session:
    """An open session folder: its manifest, its scene and the results of its finished steps."""

    def __init__(self, folder: Path, manifest: dict[str, Any], scene: Scene, budget: Budget | None = None):
        self.folder = folder
        self.manifest = manifest
        self.scene = scene
        self._results: dict[str, Any] = {}
        self._budget = Budget() if budget is None else budget  # the array bytes its files may still decompress

    @property
    def seed(self) -> int:
        return int(self.manifest["seed"])

    @property
    def records(self) -> list[dict[str, Any]]:
        return self.manifest["steps"]

    def finished(self) -> list[str]:
        return [r["name"] for r in self.records]

    def record_of(self, name: str) -> dict[str, Any]:
        return next(r for r in self.records if r["name"] == name)

    @staticmethod
    def exists(folder: Path) -> bool:
        return (folder / MANIFEST).exists()

    @classmethod
    def create(cls, folder: str | Path, scene: Scene, seed: int, force: bool = False) -> Session:
        """A new, empty session; an existing one is replaced only with `force`."""
        folder = Path(folder)
        if seed_problem(seed):  # before any folder is made: a session nothing could reopen is never written
            raise RegraspError(f"session seed: {seed_problem(seed)}")
        if cls.exists(folder):
            if not force:
                raise RegraspError(f"{folder} already holds a session; use --resume to continue it, or --force to replace it")
            cls._remove(folder)
        elif folder.exists() and (not folder.is_dir() or any(folder.iterdir())):
            raise RegraspError(f"{folder} exists and is not an empty folder (and holds no session): choose another folder")
        with writing(folder):
            folder.mkdir(parents=True, exist_ok=True)
        _save_meshes(folder, scene.meshes)
        manifest = {
            "format_version": FORMAT_VERSION,
            "task": scene.task,
            "task_source": task_reference(scene.source, folder),
            "robot_spec": scene.robot.spec.text(),
            "robot_spec_name": scene.robot.spec.source.name,
            "seed": int(seed),
            "versions": package_versions(),
            "steps": [],
        }
        session = cls(folder, manifest, scene)
        session._write_manifest()
        return session

    @staticmethod
    def _remove(folder: Path) -> None:
        """Delete a session's own files: the manifest, the meshes and the files a step writes; never a name read from the folder."""
        names = [MANIFEST, MESHES, *(f for step in PIPELINE for f in step_files(step.name))]
        with writing(folder):
            for name in names:
                (folder / name).unlink(missing_ok=True)

    def own_files(self) -> list[Path]:
        """The session's files (meshes, each finished step's files, the manifest last), as checked paths in its folder."""
        names = [MESHES, *(f for r in self.records for f in r["files"]), MANIFEST]
        return [file_in(self.folder, name, self.folder / MANIFEST, "files") for name in names]

    @classmethod
    def open(cls, folder: str | Path) -> Session:
        """Read and check a saved session: the whole manifest first, then the embedded task and every finished step's result."""
        folder = Path(folder)
        path = regular_file(folder / MANIFEST, "no session here (session.json is missing)")
        manifest = read_json_object(path)
        check_manifest(manifest, path)
        spec = cached_spec_file(manifest["robot_spec"], manifest["robot_spec_name"], path)
        try:
            load_robot(spec)
        except RegraspError as exc:
            raise InputError(path, "robot_spec", f"the embedded robot spec is not valid: {exc}") from exc
        budget = Budget()
        meshes = _load_meshes(folder, budget)
        try:
            scene = scene_from_dict(manifest["task"], path, robot_path=spec, meshes=meshes, field_prefix="task", embedded=MESHES)
        except InputError:
            raise
        except (RegraspError, TypeError, ValueError, KeyError, IndexError, AttributeError, OverflowError) as exc:
            raise InputError(path, "task", f"not a valid task ({type(exc).__name__}: {exc})") from exc
        session = cls(folder, manifest, scene, budget)
        for name in session.finished():
            session.result(name)
        return session

    def result(self, name: str) -> Any:
        """A finished step's result (read from its files once)."""
        if name not in self._results:
            if name not in self.finished():
                raise RegraspError(f"step '{name}' has not run in {self.folder}")
            self._results[name] = load_result(step_named(name).result, self.folder, name, {"nq": self.scene.robot.nq}, self._budget)
        return self._results[name]

    def record(self, step: Step, params: Any, seed: int, seconds: float, result: Any, stage_seconds: list[float] = (),
               cached: bool = False) -> None:
        """Save a finished step: its files first, then the manifest (so a crash never lists a half-written step).
        `stage_seconds` (steps with stages only) and whether the result came from the user cache are kept in the
        record, outside the result."""
        files = save_result(result, self.folder, step.name)
        self._results[step.name] = result
        entry = {"name": step.name, "params": dataclasses.asdict(params), "seed": seed, "seconds": round(seconds, 4),
                 "stats": result.stats(), "files": files}
        if stage_seconds:
            entry["stage_seconds"] = [round(float(t), 4) for t in stage_seconds]
        if cached:
            entry["cached"] = True
        order = [s.name for s in PIPELINE]
        steps = [r for r in self.records if r["name"] != step.name] + [entry]
        manifest = {**self.manifest, "steps": sorted(steps, key=lambda r: order.index(r["name"]))}
        _save_manifest(self.folder, manifest)  # the manifest in memory changes only once it is on disk
        self.manifest = manifest

    def branch(self, folder: str | Path, before: str, force: bool = False) -> Session:
        """A new session with this one's task, seed and the finished steps before `before` (copied)."""
        order = [s.name for s in PIPELINE]
        new = Session.create(folder, self.scene, self.seed, force)
        kept = [r for r in self.records if order.index(r["name"]) < order.index(before)]
        with writing(new.folder):
            for r in kept:
                for f in r["files"]:
                    shutil.copyfile(file_in(self.folder, f, self.folder / MANIFEST, "files"), new.folder / f)
        new.manifest["steps"] = [dict(r) for r in kept]
        new._write_manifest()
        return new

    def _write_manifest(self) -> None:
        _save_manifest(self.folder, self.manifest)


def _save_manifest(folder: Path, manifest: dict[str, Any]) -> None:
    atomic_write_text(folder / MANIFEST, json.dumps(manifest, indent=1, default=_plain))


def _plain(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (np.ndarray, tuple)):
        return list(value.tolist() if isinstance(value, np.ndarray) else value)
    raise TypeError(f"{type(value).__name__} is not JSON-able")
