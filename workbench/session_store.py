"""The saved sessions folder: listing it, saving a session into it (never overwriting unasked), free names."""
from __future__ import annotations

import copy
import re
import shutil
from pathlib import Path

from planner.core.errors import RegraspError
from planner.core.paths import PROJECT_ROOT, plain_name, temporary_folder
from planner.core.results import writing
from planner.core.session import Session

SESSIONS_DIR = PROJECT_ROOT / "sessions"


def list_sessions(folder: Path) -> list[str]:
    """Names of the sub-folders of `folder` that hold a session."""
    return sorted(p.name for p in folder.iterdir() if Session.exists(p)) if folder.is_dir() else []


SCRATCH_PREFIX = "regrasp-session-"


def scratch_folder() -> Path:
    """A fresh temporary folder for a session run from the GUI before it is saved (`remove_scratch` deletes it, and
    the process's exit deletes it if still there: a workbench never closed leaves none behind)."""
    return temporary_folder(SCRATCH_PREFIX) / "session"


def remove_scratch(folder: Path) -> None:
    """Delete a folder `scratch_folder` made, with the temporary folder around it."""
    if folder.parent.name.startswith(SCRATCH_PREFIX):
        shutil.rmtree(folder.parent, ignore_errors=True)


def scratch_copy(session: Session) -> Session:
    """A copy of the session, every finished step included, in a scratch folder; it shares the session's scene."""
    folder = scratch_folder()
    _copy_files(session, folder)
    return Session(folder, copy.deepcopy(session.manifest), session.scene)


def free_name(folder: Path, base: str) -> str:
    """`<base>-rerun-N` with the smallest N not taken in `folder`."""
    n = 1
    while (folder / f"{base}-rerun-{n}").exists():
        n += 1
    return f"{base}-rerun-{n}"


MAX_SESSION_NAME = 100  # characters; leaves room for `-rerun-N` and the staging folder's `.<name>.saving`
_SESSION_NAME = re.compile(r"(?!-)[\w-]+")  # letters, digits, - and _; not starting with -


def check_name(name: str) -> str:
    """A session name typed by a person: letters, digits, - and _ (not first -), at most MAX_SESSION_NAME characters."""
    name = name.strip()
    shown = repr(name) if len(name) <= 40 else repr(name[:37]) + "..."
    if len(name) > MAX_SESSION_NAME:
        raise RegraspError(f"{shown} is too long for a session name: at most {MAX_SESSION_NAME} characters")
    if not _SESSION_NAME.fullmatch(name):
        raise RegraspError(f"{shown} is not a session name: use letters, digits, - and _ (not starting with -)")
    return plain_name(name, "the Name field", "name")


def save_copy(session: Session, target: Path, overwrite: bool = False) -> Session:
    """Copy the session's files into `target`; an existing folder is replaced only with `overwrite`, and only if it holds a session."""
    if target.exists():
        if target.resolve() == session.folder.resolve():
            return session
        if not overwrite:
            raise RegraspError(f"{target} already exists: confirm to overwrite it, or choose another name")
        if not Session.exists(target):
            raise RegraspError(f"{target} exists and holds no session: choose another name")
    _copy_files(session, target)
    return Session.open(target)


def _copy_files(session: Session, target: Path) -> None:
    """Copy the session's own files into a staging folder, then swap it in for `target`; a failure leaves no staging folder."""
    staging = target.with_name(f".{target.name}.saving")
    with writing(target.parent):
        try:
            shutil.rmtree(staging, ignore_errors=True)
            staging.mkdir(parents=True)
            for path in session.own_files():
                shutil.copyfile(path, staging / path.name)
            if target.exists():
                old = target.with_name(f".{target.name}.old")
                shutil.rmtree(old, ignore_errors=True)
                target.rename(old)
                try:
                    staging.rename(target)
                except OSError:
                    old.rename(target)  # the session saved before stays where it was
                    raise
                shutil.rmtree(old)
            else:
                staging.rename(target)
        finally:
            shutil.rmtree(staging, ignore_errors=True)
