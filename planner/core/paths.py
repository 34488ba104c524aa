"""Where regrasp finds its assets, the robot descriptions of example-robot-data, and its cache."""
from __future__ import annotations

import atexit
import difflib
import functools
import importlib.metadata
import os
import shutil
import tempfile
from pathlib import Path

from planner.core.errors import InputError, RegraspError
from planner.core.results import writing

PROJECT_ROOT = Path(__file__).resolve().parents[2]
ASSETS = PROJECT_ROOT / "assets"
TASKS_DIR = ASSETS / "tasks"
DEFAULT_TASK = TASKS_DIR / "default.toml"


@functools.cache
def robot_data_share() -> Path:
    """The `share` folder of the installed example-robot-data package (holds `example-robot-data/robots`)."""
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError as exc:
        raise RegraspError("the package example-robot-data is not installed (pip install example-robot-data)") from exc
    for f in dist.files or ():
        parts = Path(str(f)).parts
        if "example-robot-data" in parts and "robots" in parts:
            full = Path(str(dist.locate_file(f)))
            i = parts.index("example-robot-data")
            return full.parents[len(parts) - i - 1]
    raise RegraspError("example-robot-data is installed but ships no robots/ folder")


def robot_data_file(relative: str) -> Path:
    """A file inside example-robot-data's `robots/` folder, e.g. 'alex_description/urdf/alex_nub_hands.urdf'."""
    return robot_data_share() / "example-robot-data" / "robots" / relative


def temporary_folder(prefix: str) -> Path:
    """A new temporary folder, deleted with what it holds when this process exits (not when a child forked from it
    does, which inherits the exit handler): a run that ends without tidying up leaves none behind."""
    folder = Path(tempfile.mkdtemp(prefix=prefix))
    atexit.register(_remove_if_owner, folder, os.getpid())
    return folder


def _remove_if_owner(folder: Path, owner: int) -> None:
    if os.getpid() == owner:
        shutil.rmtree(folder, ignore_errors=True)


def cache_dir() -> Path:
    """The user cache folder ($REGRASP_CACHE, else $XDG_CACHE_HOME/regrasp, else ~/.cache/regrasp)."""
    env = os.environ.get("REGRASP_CACHE")
    if env:
        base = Path(env)
    else:
        base = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "regrasp"
    with writing(base):
        base.mkdir(parents=True, exist_ok=True)
    return base


MAX_NAME_BYTES = 200  # below NAME_MAX (255) so that `.<name>.saving`-style staging names still fit


def plain_name(value: object, source: str | Path, field: str) -> str:
    """A file name read from a file, checked to be one plain name (the only way such names become paths)."""
    if not isinstance(value, str):
        raise InputError(source, field, f"expected a file name (a string), got {type(value).__name__}")
    if value in ("", ".", ".."):
        raise InputError(source, field, f"expected a file name, got {value!r}")
    bad = sorted({c for c in value if c in "/\\\0" or not c.isprintable()})
    if bad:
        raise InputError(source, field, f"expected a plain file name (no folder separators or control characters), got {value!r}")
    if len(value.encode("utf-8", "surrogatepass")) > MAX_NAME_BYTES:
        size = len(value.encode("utf-8", "surrogatepass"))
        raise InputError(source, field, f"expected a file name of at most {MAX_NAME_BYTES} bytes, got {size}")
    return value


def file_in(folder: Path, value: object, source: str | Path, field: str) -> Path:
    """`folder / value` for a name read from `source` (field `field`), refused unless it is a plain file name."""
    return folder / plain_name(value, source, field)


def named_file(text: str | Path, folder: Path, what: str) -> Path:
    """The file `text` names: an existing file, else a name in `folder` (with or without `.toml`), e.g. a task in assets/tasks/.

    An unknown one is an InputError listing the names there are, with the closest as "did you mean"."""
    path = Path(text)
    if path.is_file():
        return path
    names = sorted(p.stem for p in folder.glob("*.toml"))
    stem = path.name.removesuffix(".toml")
    if path.parent == Path(".") and stem in names:
        return folder / f"{stem}.toml"
    close = difflib.get_close_matches(stem, names, n=1)
    hint = f"did you mean '{close[0]}'? " if close else ""
    where = folder.relative_to(PROJECT_ROOT) if folder.is_relative_to(PROJECT_ROOT) else folder
    raise InputError(path, None, f"file not found, nor a {what} name in {where}/ ({hint}{what}s: {', '.join(names) or 'none'})")
