"""Reading .npz files from untrusted folders without a decompression bomb: only the entries asked for are read, and each
entry's .npy header (dtype, shape, hence its size) is checked against what the reader declares, and against the zip
entry's own uncompressed size, before a byte of its data is decompressed."""
from __future__ import annotations

import contextlib
import io
import math
import zipfile
import zlib
from collections.abc import Callable, Collection, Iterator
from pathlib import Path
from types import TracebackType

import numpy as np

from planner.core.errors import InputError

MAX_ARRAY_BYTES = 256 * 2**20  # one array: the example session's largest is 1.8 MB
MAX_READ_BYTES = 1024 * 2**20  # every array read for one session (or from one file read alone)
Shape = tuple[int | str | None, ...]  # an int, a name of a dimension shared between arrays, or None for any


def npz_bytes(arrays: dict[str, np.ndarray]) -> bytes:
    """The bytes of an .npz file of `arrays`, each entry deflated: step results, sessions and the user cache are
    written so (sizes in docs/benchmarks.md); files written before, stored plain, read as well."""
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    return buf.getvalue()


def shape_text(shape: Shape) -> str:
    return "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"


@contextlib.contextmanager
def _readable(path: Path, field: str | None) -> Iterator[None]:
    """Turn what zipfile and numpy raise on a truncated, corrupt or crafted file into one InputError naming it."""
    try:
        yield
    # NotImplementedError: what zipfile raises for a compression method it does not support (a crafted entry)
    except (zipfile.BadZipFile, zlib.error, ValueError, OSError, EOFError, KeyError, NotImplementedError) as exc:
        raise InputError(path, field, f"not a readable .npz file (truncated or corrupt: {type(exc).__name__}: {exc})") from exc


class Budget:
    """The bytes of array data that may still be decompressed: one budget is shared by every file of a session, so
    that many files of legal arrays cannot add up to a bomb either."""

    def __init__(self, total: int | None = None):
        self.total = MAX_READ_BYTES if total is None else total
        self.left = self.total

    def spend(self, size: int, path: Path, field: str) -> None:
        if size > self.left:
            raise InputError(path, field, f"its {size:,} bytes would bring the arrays read to more than the "
                                          f"{self.total:,} bytes allowed for one session")
        self.left -= size


class NpzFile:
    """An open .npz file read entry by entry: `header` checks an entry before `read` decompresses it."""

    def __init__(self, path: Path, budget: Budget | None = None):
        self.path = path
        self.budget = Budget() if budget is None else budget
        with _readable(path, None):
            self._zip = zipfile.ZipFile(path)
        self._checked: dict[str, int] = {}  # entry -> its data's size in bytes, once its header is checked

    def __enter__(self) -> NpzFile:
        return self

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None) -> None:
        self._zip.close()

    def names(self) -> list[str]:
        """The array names the file holds (its entries' names without `.npy`)."""
        return [n.removesuffix(".npy") for n in self._zip.namelist()]

    def header(self, name: str, dtype: np.dtype, shape: Shape, dims: dict[str, int] | None = None,
               check: Callable[[tuple[int, ...]], None] | None = None, max_bytes: int = MAX_ARRAY_BYTES) -> tuple[int, ...]:
        """The shape of array `name`, checked without reading its data: its dtype (a flexible one such as "U" by kind),
        its shape (names in `dims` agreeing between arrays; then `check`, the caller's own limits, if given), its size
        (`max_bytes`, and what is left of the budget) and the zip entry's uncompressed size."""
        try:
            info = self._zip.getinfo(f"{name}.npy")
        except KeyError:
            raise InputError(self.path, name, "missing array") from None
        with _readable(self.path, name), self._zip.open(info) as f:
            version = np.lib.format.read_magic(f)
            if version not in ((1, 0), (2, 0)):
                raise InputError(self.path, name, f"an .npy header of version {version}; expected 1.0 or 2.0")
            read = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
            got_shape, _, got = read(f)
            offset = f.tell()
        same = got.kind == dtype.kind if dtype.itemsize == 0 else got == dtype
        if got.hasobject or not same:
            raise InputError(self.path, name, f"expected dtype {dtype}, got {got}")
        if len(got_shape) != len(shape):
            raise InputError(self.path, name, f"expected {len(shape)} dimensions {shape_text(shape)}, got shape {got_shape}")
        dims = {} if dims is None else dims
        for n, want in zip(got_shape, shape):
            if isinstance(want, int) and n != want:
                raise InputError(self.path, name, f"expected shape {shape_text(shape)}, got {got_shape}")
            if isinstance(want, str) and dims.setdefault(want, n) != n:
                raise InputError(self.path, name, f"expected shape {shape_text(shape)} with {want} = {dims[want]}, got {got_shape}")
        if check is not None:
            check(tuple(got_shape))
        size = math.prod(got_shape) * got.itemsize
        if size > max_bytes:
            raise InputError(self.path, name, f"declares {got_shape} {got}: {size:,} bytes, more than the {max_bytes:,} "
                                               "allowed for this array")
        if info.file_size != offset + size:
            raise InputError(self.path, name, f"its header declares {size:,} bytes of data but the entry holds "
                                               f"{info.file_size - offset:,}: truncated or corrupt")
        if name not in self._checked:
            self.budget.spend(size, self.path, name)
        self._checked[name] = size
        return tuple(got_shape)

    def read(self, name: str) -> np.ndarray:
        """The data of an array whose header `header` checked (no pickles)."""
        if name not in self._checked:
            raise ValueError(f"read {name} before checking its header")
        with _readable(self.path, name), self._zip.open(f"{name}.npy") as f:
            return np.lib.format.read_array(f, allow_pickle=False)


def read_npz(path: Path, declared: dict[str, tuple[np.dtype, Shape]], dims: dict[str, int] | None = None,
             budget: Budget | None = None, optional: Collection[str] = ()) -> dict[str, np.ndarray]:
    """The arrays `declared` (name -> dtype and shape) of an .npz file, every header checked before any data is read;
    other entries are never read. `dims` fixes (and collects) the named dimensions; an `optional` array the file does
    not hold is left out of the answer."""
    with NpzFile(path, budget) as npz:
        held = set(npz.names())
        wanted = [name for name in declared if name in held or name not in optional]
        for name in wanted:
            npz.header(name, *declared[name], dims)
        return {name: npz.read(name) for name in wanted}
