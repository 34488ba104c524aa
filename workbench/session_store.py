"""The saved sessions folder: listing it, saving a session into it (never overwriting unasked), free names; scratch
sessions (runs from the GUI before they are saved), whose unsaved steps are kept there before they are deleted."""
from __future__ import annotations

import copy
import re
import shutil
from pathlib import Path

from planner.core.errors import RegraspError
from planner.core.paths import PROJECT_ROOT, plain_name, temporary_folder
from planner.core.results import writing
from planner.core.session import Session
from planner.model.task import Scene

from .notify import error_text

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


def free_name(folder: Path, base: str, kind: str = "rerun") -> str:
    """`<base>-<kind>-N` with the smallest N not taken in `folder`."""
    n = 1
    while (folder / f"{base}-{kind}-{n}").exists():
        n += 1
    return f"{base}-{kind}-{n}"


def unsaved_steps(records: list, saved: list | None) -> list[str]:
    """The names of the step `records` not among the `saved` ones (the records when last saved) as they are."""
    kept = {r["name"]: r for r in saved or []}
    return [r["name"] for r in records if kept.get(r["name"]) != r]


def keep_unsaved(folder: Path, sessions_dir: Path, saved: list | None) -> Path | None:
    """Copy a scratch session about to be deleted into `sessions_dir/<task>-unsaved-N` (listed with the saved sessions)
    when it has finished steps not saved as they are (`saved`: its step records when it was last saved); the copy's
    folder, or None when there was nothing to keep."""
    session = Session.open(folder)
    if not unsaved_steps(session.records, saved):
        return None
    return save_copy(session, sessions_dir / unsaved_name(sessions_dir, session.scene)).folder


def unsaved_name(sessions_dir: Path, scene: Scene) -> str:
    """The free `<task>-unsaved-N` name unsaved steps of a session of `scene` are kept under in `sessions_dir`."""
    try:
        base = check_name(scene.name)
    except RegraspError:  # a task name that is no folder name
        base = "untitled"
    return free_name(sessions_dir, base, "unsaved")


def discard_scratch(folder: Path, sessions_dir: Path, saved: list | None) -> tuple[str, str, bool] | None:
    """Delete a scratch session once `keep_unsaved` kept what it must; what to say (title, text, whether an error), if
    anything. A copy that fails leaves the folder until the process ends."""
    try:
        kept = keep_unsaved(folder, sessions_dir, saved)
    except Exception as exc:  # e.g. a read-only sessions folder: said, never raised into the GUI's callback
        return "Unsaved work not kept", f"{error_text(exc)}; it is in {folder} until the workbench stops", True
    remove_scratch(folder)
    return ("Unsaved work kept", f"the steps run here are in {kept}: Load it from Saved", False) if kept else None


MAX_SESSION_NAME = 100  # characters; leaves room for `-rerun-N` (`-unsaved-N`) and the staging folder's `.<name>.saving`
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
