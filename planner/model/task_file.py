"""Writing a task back to a TOML file (the workbench's "Save task as"): what `load_task` reads, it writes.

A task written to another folder than the one it was read from names the same robot spec and mesh files: each file
reference is re-expressed for the new folder (by its name when it lies in the folder the loader searches, else by a
path relative to the task file). A task file is written whole or not at all, and an existing one is replaced only when
the caller says so; the file's name is one plain name checked here, so a typed name never leaves its folder.
"""
from __future__ import annotations

import copy
import os
import re
from pathlib import Path
from typing import Any

from planner.core.errors import RegraspError
from planner.core.results import atomic_write_text, writing
from planner.core.toml_text import toml_text
from planner.model.task import BUILTIN_OBJECTS, OBJECTS_DIR, ROBOTS_DIR, find_file

MAX_TASK_NAME = 80  # characters of a task's file name (without .toml)
_TASK_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]*")
HEADER = "# Written by the regrasp workbench (docs/workbench.md, \"Editing the task\"); the format is in docs/tasks.md.\n"


def check_task_name(name: str) -> str:
    """A task name typed by a person: letters, digits, - and _, starting with a letter or digit (it names the file)."""
    name = name.strip().removesuffix(".toml")
    shown = repr(name) if len(name) <= 40 else repr(name[:37]) + "..."
    if len(name) > MAX_TASK_NAME:
        raise RegraspError(f"{shown} is too long for a task name: at most {MAX_TASK_NAME} characters")
    if not _TASK_NAME.fullmatch(name):
        raise RegraspError(f"{shown} is not a task name: use letters, digits, - and _ (starting with a letter or digit)")
    return name


def task_path(folder: Path, name: str) -> Path:
    """Where the task `name` (checked by `check_task_name`) is written in `folder`."""
    return folder / f"{check_task_name(name)}.toml"


def file_reference(path: Path, folder: Path, search: Path) -> str:
    """How a task file in `folder` names the file `path`: by its path within `search` (the folder the loader looks in
    after the task's own) when it lies there and no file of that name sits beside the task, else relative to `folder`."""
    path, search = path.resolve(), search.resolve()
    if path.is_relative_to(search):
        inside = path.relative_to(search).as_posix()
        if find_file(inside, folder, search) == path:
            return inside
    return Path(os.path.relpath(path, folder.resolve())).as_posix()


def _rebase(table: dict[str, Any], key: str, source: Path, folder: Path, search: Path) -> None:
    """Re-express `table[key]`, a file reference read beside `source`, for a task file in `folder`."""
    value = table.get(key)
    if not isinstance(value, str) or (search == OBJECTS_DIR and value in BUILTIN_OBJECTS):
        return
    found = find_file(value, source.parent, search)
    if found is None:
        raise RegraspError(f"{source}: field '{key}': file '{value}' not found (looked beside the task file and in {search})")
    table[key] = file_reference(found, folder, search)


def rebased(data: dict[str, Any], source: Path, target: Path) -> dict[str, Any]:
    """A copy of task data read from `source` whose file references (the robot spec, the object's and obstacles'
    meshes) name the same files from `target`."""
    data = copy.deepcopy(data)
    _rebase(data, "robot", source, target.parent, ROBOTS_DIR)
    if isinstance(data.get("object"), dict):
        _rebase(data["object"], "mesh", source, target.parent, OBJECTS_DIR)
    for obstacle in data.get("obstacles", []):
        if isinstance(obstacle, dict):
            _rebase(obstacle, "mesh", source, target.parent, OBJECTS_DIR)
    return data


def write_task(data: dict[str, Any], source: Path, target: Path, overwrite: bool = False) -> Path:
    """Write task data read from `source` (a task file, or where an edited task's references are read from) to the task
    file `target`; an existing file is replaced only with `overwrite`. Returns `target`."""
    text = HEADER + toml_text(rebased(data, source, target))
    with writing(target.parent):
        target.parent.mkdir(parents=True, exist_ok=True)
        if overwrite:
            atomic_write_text(target, text)
            return target
        staged = target.with_name(f".{target.name}.new{os.getpid()}")
        try:
            atomic_write_text(staged, text)
            os.link(staged, target)  # fails if the file exists, even if it appeared a moment ago
        except FileExistsError:
            raise RegraspError(f"{target} already exists: confirm to overwrite it, or choose another name") from None
        finally:
            staged.unlink(missing_ok=True)
    return target
