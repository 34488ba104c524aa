"""Keys and files of the user cache (offline results keyed by a hash of everything they depend on)."""
from __future__ import annotations

import hashlib
import io
from pathlib import Path

import numpy as np

from .paths import cache_dir
from .results import atomic_write_bytes


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
    folder.mkdir(parents=True, exist_ok=True)
    return folder / key


def save_arrays(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """Write arrays to an .npz atomically (two processes may fill the cache at once)."""
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    atomic_write_bytes(path, buf.getvalue())


def load_arrays(path: Path) -> dict[str, np.ndarray] | None:
    """The arrays of a cached .npz, or None when it is absent or unreadable."""
    try:
        with np.load(path, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except (OSError, ValueError, EOFError):
        return None
