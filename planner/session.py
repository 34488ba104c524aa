"""Sessions: a folder holding a task, the results of the steps run on it, and how they were run.

`session.json` (written last, atomically) has `format_version`, `task` (the task data in full),
`robot_spec` (the spec's text), `seed`, `versions` and `steps`: in pipeline order, one
`{"name", "params", "seed", "seconds", "stats", "files"}` per finished step. `task_meshes.npz`
holds every mesh the task names, so a replay needs no task file. Each step writes
`<step>.npz` + `<step>.json` (see `results.py`).
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import platform
import shutil
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from . import __version__
from .errors import InputError, RegraspError
from .paths import cache_dir
from .pipeline import PIPELINE, step_named
from .results import atomic_write_text, load_result, read_json_object, save_result
from .steps import Step
from .task import Scene, scene_from_dict

FORMAT_VERSION = 1
MANIFEST = "session.json"
MESHES = "task_meshes.npz"
STEP_KEYS = ("name", "params", "seed", "seconds", "stats", "files")


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
    tmp = folder / f".{MESHES}.tmp.npz"
    np.savez(tmp, **arrays)
    tmp.replace(folder / MESHES)


def _load_meshes(folder: Path) -> dict[str, trimesh.Trimesh]:
    path = folder / MESHES
    if not path.is_file():
        raise InputError(path, None, "missing: the session's embedded meshes are gone")
    try:
        with np.load(path, allow_pickle=False) as npz:
            n = len([k for k in npz.files if k.endswith("_key")])
            return {str(npz[f"{i}_key"]): trimesh.Trimesh(npz[f"{i}_vertices"], npz[f"{i}_faces"], process=False) for i in range(n)}
    except (ValueError, OSError, EOFError, KeyError) as exc:
        raise InputError(path, None, f"not a readable .npz file (truncated or corrupt: {exc})") from exc


def _spec_file(text: str, name: str) -> Path:
    """The embedded robot spec written to the user cache (content-addressed), to load it from there."""
    folder = cache_dir() / "specs" / hashlib.sha256(text.encode()).hexdigest()[:16]
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    if not path.is_file() or path.read_text() != text:
        atomic_write_text(path, text)
    return path


class Session:
    """An open session folder: its manifest, its scene and the results of its finished steps."""

    def __init__(self, folder: Path, manifest: dict[str, Any], scene: Scene):
        self.folder = folder
        self.manifest = manifest
        self.scene = scene
        self._results: dict[str, Any] = {}

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
    def create(cls, folder: str | Path, scene: Scene, seed: int, force: bool = False) -> "Session":
        """A new, empty session; an existing one is replaced only with `force`."""
        folder = Path(folder)
        if cls.exists(folder):
            if not force:
                raise RegraspError(f"{folder} already holds a session; use --resume to continue it, or --force to replace it")
            cls._remove(folder)
        elif folder.exists() and any(folder.iterdir()):
            raise RegraspError(f"{folder} exists and is not empty (and holds no session): choose another folder")
        folder.mkdir(parents=True, exist_ok=True)
        _save_meshes(folder, scene.meshes)
        manifest = {
            "format_version": FORMAT_VERSION,
            "task": scene.task,
            "task_source": str(scene.source),
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
        """Delete a session's own files (the manifest, the meshes, each step's files), nothing else."""
        try:
            manifest = json.loads((folder / MANIFEST).read_text())
            files = [f for r in manifest.get("steps", []) for f in r.get("files", [])]
        except (json.JSONDecodeError, OSError, AttributeError, TypeError):
            files = []
        for name in [MANIFEST, MESHES, *files]:
            (folder / name).unlink(missing_ok=True)

    @classmethod
    def open(cls, folder: str | Path) -> "Session":
        """Read and check a saved session: manifest, embedded task, and every finished step's result."""
        folder = Path(folder)
        path = folder / MANIFEST
        if not path.is_file():
            raise InputError(path, None, "no session here (session.json is missing)")
        manifest = read_json_object(path)
        for key in ("format_version", "task", "robot_spec", "robot_spec_name", "seed", "versions", "steps"):
            if key not in manifest:
                raise InputError(path, key, "missing field")
        version = manifest["format_version"]
        if not isinstance(version, int) or version > FORMAT_VERSION:
            raise InputError(path, "format_version", f"format {version!r} was written by a newer regrasp; this one reads formats up to {FORMAT_VERSION}")
        if not isinstance(manifest["task"], dict):
            raise InputError(path, "task", "expected the task as a JSON object")
        if not isinstance(manifest["steps"], list):
            raise InputError(path, "steps", "expected a list")
        spec = _spec_file(manifest["robot_spec"], manifest["robot_spec_name"])
        scene = scene_from_dict(manifest["task"], path, robot_path=spec, meshes=_load_meshes(folder), field_prefix="task")
        session = cls(folder, manifest, scene)
        for i, record in enumerate(manifest["steps"]):
            field = f"steps[{i}]"
            if not isinstance(record, dict) or any(k not in record for k in STEP_KEYS):
                raise InputError(path, field, f"expected an object with {', '.join(STEP_KEYS)}")
            try:
                step_named(record["name"])
            except RegraspError as exc:
                raise InputError(path, f"{field}.name", str(exc)) from exc
            session.result(record["name"])
        return session

    def result(self, name: str) -> Any:
        """A finished step's result (read from its files once)."""
        if name not in self._results:
            if name not in self.finished():
                raise RegraspError(f"step '{name}' has not run in {self.folder}")
            self._results[name] = load_result(step_named(name).result, self.folder, name, {"nq": self.scene.robot.nq})
        return self._results[name]

    def record(self, step: Step, params: Any, seed: int, seconds: float, result: Any, stage_seconds: list[float] = ()) -> None:
        """Save a finished step: its files first, then the manifest (so a crash never lists a half-written step).
        `stage_seconds` (steps with stages only) are kept in the record, outside the result."""
        files = save_result(result, self.folder, step.name)
        self._results[step.name] = result
        entry = {"name": step.name, "params": dataclasses.asdict(params), "seed": seed, "seconds": round(seconds, 4),
                 "stats": result.stats(), "files": files}
        if stage_seconds:
            entry["stage_seconds"] = [round(float(t), 4) for t in stage_seconds]
        order = [s.name for s in PIPELINE]
        steps = [r for r in self.records if r["name"] != step.name] + [entry]
        self.manifest["steps"] = sorted(steps, key=lambda r: order.index(r["name"]))
        self._write_manifest()

    def branch(self, folder: str | Path, before: str, force: bool = False) -> "Session":
        """A new session with this one's task, seed and the finished steps before `before` (copied)."""
        order = [s.name for s in PIPELINE]
        new = Session.create(folder, self.scene, self.seed, force)
        kept = [r for r in self.records if order.index(r["name"]) < order.index(before)]
        for r in kept:
            for f in r["files"]:
                shutil.copy2(self.folder / f, new.folder / f)
        new.manifest["steps"] = [dict(r) for r in kept]
        new._write_manifest()
        return new

    def _write_manifest(self) -> None:
        atomic_write_text(self.folder / MANIFEST, json.dumps(self.manifest, indent=1, default=_plain))


def _plain(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (np.ndarray, tuple)):
        return list(value.tolist() if isinstance(value, np.ndarray) else value)
    raise TypeError(f"{type(value).__name__} is not JSON-able")
