"""Keys and files of the user cache (offline results keyed by a hash of everything they depend on).

Caches are disposable: an entry that cannot be read is deleted, recomputed, and the user told so in one line. Entries are
written atomically, and an entry being computed is locked (`computing`): processes needing the same entry (a suite's
workers) compute it once, the others wait for it and read it. Building an entry is logged when it starts and when it is
stored (`building`, at INFO level: `regrasp suite` prints these lines, so a cold run shows what it is waiting for)."""
from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import logging
import os
import time
import zipfile
import zlib
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import TypeVar

import numpy as np

from planner.core.errors import RegraspError
from planner.core.npz import npz_bytes
from planner.core.paths import cache_dir
from planner.core.results import atomic_write_bytes, writing

T = TypeVar("T")
log = logging.getLogger("regrasp.cache")
# what reading a damaged entry raises: bad files, bad JSON, bad archives, missing or mistyped fields
UNREADABLE = (RegraspError, OSError, ValueError, EOFError, KeyError, TypeError, IndexError, zipfile.BadZipFile, zlib.error,
              json.JSONDecodeError, UnicodeDecodeError)


def cache_key(*parts: str | bytes) -> str:
    """A short hash of the inputs (code version, spec and mesh bytes, parameters...)."""
    h = hashlib.sha256()
    for part in parts:
        data = part.encode() if isinstance(part, str) else part
        h.update(len(data).to_bytes(8, "little"))
        h.update(data)
    return h.hexdigest()[:24]


def cache_path(kind: str, key: str) -> Path:
    """The cache folder of one kind of result (created), joined with a key."""
    folder = cache_dir() / kind
    with writing(folder):
        folder.mkdir(parents=True, exist_ok=True)
    return folder / key


@contextlib.contextmanager
def computing(entry: Path) -> Iterator[None]:
    """Held while this process reads or computes a cache entry: another process asking for the same entry waits (flock)."""
    with writing(entry.parent):
        fd = os.open(entry.parent / f".{entry.name}.lock", os.O_CREAT | os.O_RDWR, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)


@contextlib.contextmanager
def building(what: str) -> Iterator[None]:
    """Around the computation and storing of a cache entry (`what` names it): a log line as it starts, and one with its
    seconds once it is stored (none when it fails)."""
    log.info("cache: building %s ...", what)
    start = time.perf_counter()
    yield
    log.info("cache: built %s in %.1f s", what, time.perf_counter() - start)


def read_cached(files: Sequence[Path], read: Callable[[], T], what: str) -> T | None:
    """`read()` of a cache entry made of `files`; None when absent, and when unreadable: the files deleted and a one-line warning."""
    if not all(f.exists() for f in files):
        return None
    try:
        return read()
    except UNREADABLE as exc:
        for f in files:
            f.unlink(missing_ok=True)
        cause = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        log.warning("warning: the cached %s in %s could not be read (%s); deleted it, recomputing", what, files[0].parent, cause)
        return None


def save_arrays(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """Write arrays to an .npz atomically (two processes may fill the cache at once)."""
    atomic_write_bytes(path, npz_bytes(arrays))


def load_arrays(path: Path, what: str | None = None, keys: Sequence[str] = ()) -> dict[str, np.ndarray] | None:
    """The arrays of a cached .npz holding at least `keys`, or None when it is absent or unreadable (then deleted, with a warning);
    `what` names the entry in the warning (default: its cache folder's name)."""
    def read() -> dict[str, np.ndarray]:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        missing = [k for k in keys if k not in arrays]
        if missing:
            raise KeyError(f"no array {missing[0]}")
        return arrays
    return read_cached([path], read, what or path.parent.name)
