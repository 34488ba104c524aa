"""Meshes uploaded from the browser: size-limited, named safely, checked as `regrasp check` checks a task's mesh, and
stored in the workbench's uploads folder, where a task file names them (`uploaded/<name>`, looked up in assets/objects).

A file is refused by its declared size before its bytes are taken (the client guard, `MAX_UPLOAD_BYTES`), and again by
its real size here; its name is reduced to one plain file name, so no name leaves the folder; a stored mesh is never
replaced: an upload of another file under a taken name gets a free one.
"""
from __future__ import annotations

import hashlib
import os
import re
from pathlib import Path

from planner.core.errors import InputError
from planner.core.results import atomic_write_bytes, writing
from planner.model.object_mesh import FORMATS, OBJECT_LIMITS, load_mesh, mesh_format
from planner.model.task import OBJECTS_DIR

UPLOADS_DIR = OBJECTS_DIR / "uploaded"  # a task file names an upload `uploaded/<name>`: the loader looks in assets/objects
MAX_UPLOAD_BYTES = 32 * 1024 * 1024  # a 200,000-triangle mesh (the most a task takes) is under 20 MB in any format
MAX_STEM = 60  # characters kept of an uploaded file's name (without its extension)
MAX_SUFFIX = 8  # characters kept of its extension (one a mesh is read from is shorter)
ACCEPTED = ",".join(FORMATS)  # the upload button's file filter
_UNSAFE = re.compile(r"[^A-Za-z0-9_-]+")


def too_large(size: int) -> str | None:
    """Why an upload of `size` bytes is refused, or None."""
    if size > MAX_UPLOAD_BYTES:
        return f"is {size:,} bytes, more than the {MAX_UPLOAD_BYTES:,} bytes ({MAX_UPLOAD_BYTES / 2**20:g} MB) an uploaded mesh may be"
    return None


def upload_name(filename: str) -> str:
    """A plain file name for an uploaded file: its last path component, letters, digits, - and _ kept (others become _),
    the extension lower-cased and one a mesh is read from (the same message as `regrasp check` otherwise)."""
    base = re.split(r"[/\\]", filename)[-1]
    stem, dot, suffix = base.rpartition(".")
    if not dot:
        stem, suffix = base, ""
    stem = _UNSAFE.sub("_", stem).strip("_-")[:MAX_STEM] or "mesh"
    suffix = _UNSAFE.sub("_", suffix.lower())[:MAX_SUFFIX]
    name = f"{stem}.{suffix}" if suffix else stem
    mesh_format(Path(name))  # an unsupported format is refused before any byte is kept
    return name


def _free(folder: Path, name: str, content: bytes) -> tuple[Path, bool]:
    """Where `content` is stored under `name` or a free variant `<stem>-N`: (path, whether it is already there)."""
    stem, suffix = name.rsplit(".", 1)
    digest = hashlib.sha256(content).digest()
    for n in range(1, 10_000):
        path = folder / (name if n == 1 else f"{stem}-{n}.{suffix}")
        if not path.exists():
            return path, False
        if path.is_file() and path.stat().st_size == len(content) and hashlib.sha256(path.read_bytes()).digest() == digest:
            return path, True
    raise InputError(folder, None, f"holds 10,000 uploads named like {name!r}; remove some")


def store_upload(filename: str, content: bytes, folder: Path = UPLOADS_DIR) -> Path:
    """Check an uploaded object mesh and keep it in `folder`; an InputError naming the uploaded file says what is wrong
    (the text `regrasp check` gives for the same file in a task)."""
    name = upload_name(filename)
    problem = too_large(len(content))
    if problem is not None:
        raise InputError(name, None, problem)
    with writing(folder):
        folder.mkdir(parents=True, exist_ok=True)
        staged = folder / f".upload{os.getpid()}-{name}"  # hidden, and of the upload's format
        try:
            atomic_write_bytes(staged, content)
            try:
                load_mesh(staged, OBJECT_LIMITS)
            except InputError as exc:  # the checks of a task's mesh file, reported at the uploaded file's name
                raise InputError(name, None, f"the object mesh {exc.detail}") from None
            path, there = _free(folder, name, content)
            if not there:
                os.link(staged, path)
        finally:
            staged.unlink(missing_ok=True)
    return path
