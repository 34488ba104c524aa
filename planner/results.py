"""Step results: frozen dataclasses that write themselves into a session and read themselves back.

Fields declared with `array(dtype, shape)` go to the step's `.npz` (shape entries: an int, or a
name like "n" shared between fields (the session fixes "nq" to the robot's DoF), or None for any); every other field must be JSON-able
(numbers, strings, bools, lists, dicts) and goes to the step's `.json`. Loading checks every
array's dtype and shape and every JSON field's presence, with errors naming the file and field.
"""
from __future__ import annotations

import contextlib
import dataclasses
import errno
import io
import json
import os
import zipfile
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from .errors import InputError, RegraspError

R = TypeVar("R")


def array(dtype: str, shape: tuple[int | str | None, ...]) -> Any:
    """Declare a numpy-array field of a result: saved to the .npz and checked on load."""
    return dataclasses.field(metadata={"dtype": np.dtype(dtype).str, "shape": shape})


def _is_array(f: dataclasses.Field) -> bool:
    return "dtype" in f.metadata


class OutputError(RegraspError):
    """A folder regrasp could not write into (no permission, read-only file system, disk full...): names it and the cause."""

    def __init__(self, folder: Path, exc: OSError):
        self.folder = Path(folder)
        self.errno = exc.errno
        cause = os.strerror(exc.errno) if exc.errno else str(exc)
        code = f" [{errno.errorcode[exc.errno]}]" if exc.errno in errno.errorcode else ""
        other = exc.filename is not None and not Path(os.fsdecode(exc.filename)).is_relative_to(self.folder)
        super().__init__(f"could not write to {self.folder}: {cause}{code}" + (f" ({exc.filename})" if other else ""))


@contextlib.contextmanager
def writing(folder: Path) -> Iterator[None]:
    """Turn an OSError raised while writing into `folder` into one OutputError naming the folder and the cause."""
    try:
        yield
    except OSError as exc:
        raise OutputError(folder, exc) from exc


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write to a temporary file in the same folder, then rename: a crash never leaves half a file, a failure no temporary one."""
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    with writing(path.parent):
        try:
            with open(tmp, "wb") as f:
                f.write(data)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, path)
        except BaseException:
            with contextlib.suppress(OSError):
                tmp.unlink(missing_ok=True)
            raise


def atomic_write_text(path: Path, text: str) -> None:
    atomic_write_bytes(path, text.encode())


def frozen(a: np.ndarray) -> np.ndarray:
    """`a` itself, made read-only: an array shared after it is built (a robot's, a planner's result, a memoised order)."""
    a.setflags(write=False)
    return a


def read_only(result: R) -> R:
    """`result` with its array fields made read-only (results are immutable once built, like loaded ones)."""
    for f in dataclasses.fields(result):
        if _is_array(f):
            getattr(result, f.name).setflags(write=False)
    return result


def save_result(result: Any, folder: Path, stem: str) -> list[str]:
    """Write a result as `<stem>.npz` (arrays) and `<stem>.json` (the rest); returns the file names."""
    arrays, rest = {}, {}
    for f in dataclasses.fields(result):
        value = getattr(result, f.name)
        if _is_array(f):
            arrays[f.name] = np.ascontiguousarray(value, dtype=np.dtype(f.metadata["dtype"]))
        else:
            rest[f.name] = value
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    atomic_write_bytes(folder / f"{stem}.npz", buf.getvalue())
    atomic_write_text(folder / f"{stem}.json", json.dumps(rest, indent=1, default=_json_default))
    return [f"{stem}.npz", f"{stem}.json"]


def _json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, tuple):
        return list(value)
    raise TypeError(f"{type(value).__name__} is not JSON-able: declare it with results.array(...)")


def regular_file(path: Path, missing: str) -> Path:
    """`path` if it is a regular file (not a link, a folder or a device); else an InputError (`missing` says why it should be there)."""
    if path.is_symlink():
        raise InputError(path, None, "a symbolic link: a session's files must be plain files inside its folder")
    if not path.exists():
        raise InputError(path, None, f"missing: {missing}")
    if not path.is_file():
        raise InputError(path, None, "not a regular file")
    return path


def read_json_object(path: Path) -> dict[str, Any]:
    """A JSON file that must hold an object; anything else is an InputError naming the file."""
    try:
        data = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError, RecursionError) as exc:
        raise InputError(path, None, f"not valid JSON ({type(exc).__name__}: {exc})") from exc
    except OSError as exc:
        raise InputError(path, None, f"cannot be read ({os.strerror(exc.errno) if exc.errno else exc})") from exc
    if not isinstance(data, dict):
        raise InputError(path, None, "expected a JSON object")
    return data


def load_result(cls: type[R], folder: Path, stem: str, dims: dict[str, int] | None = None) -> R:
    """Read a result written by `save_result`, checking every field; errors name the file and field.

    `dims` fixes named dimensions known from the scene (e.g. nq, the robot's DoF)."""
    npz_path, json_path = folder / f"{stem}.npz", folder / f"{stem}.json"
    for p in (npz_path, json_path):
        regular_file(p, "the session lists this step as finished but its file is gone")
    rest = read_json_object(json_path)
    arrays = read_npz(npz_path)
    values: dict[str, Any] = {}
    dims = dict(dims or {})
    for f in dataclasses.fields(cls):
        if _is_array(f):
            if f.name not in arrays:
                raise InputError(npz_path, f.name, "missing array")
            values[f.name] = _checked(arrays[f.name], f, npz_path, dims)
        else:
            if f.name not in rest:
                raise InputError(json_path, f.name, "missing field")
            values[f.name] = rest[f.name]
    unknown = set(rest) - set(values)
    if unknown:
        raise InputError(json_path, sorted(unknown)[0], f"unknown field (this version of {cls.__name__} does not have it)")
    return cls(**values)


def read_npz(path: Path) -> dict[str, np.ndarray]:
    """Every array of an .npz file (no pickles); a truncated or corrupt file is an InputError naming it."""
    try:
        with np.load(path, allow_pickle=False) as npz:
            return {k: npz[k] for k in npz.files}
    # NotImplementedError: what zipfile raises for a compression method it does not support (a crafted entry)
    except (zipfile.BadZipFile, zlib.error, ValueError, OSError, EOFError, KeyError, NotImplementedError) as exc:
        raise InputError(path, None, f"not a readable .npz file (truncated or corrupt: {type(exc).__name__}: {exc})") from exc


def _checked(value: np.ndarray, f: dataclasses.Field, path: Path, dims: dict[str, int]) -> np.ndarray:
    want_dtype, want_shape = np.dtype(f.metadata["dtype"]), f.metadata["shape"]
    if value.dtype != want_dtype:
        raise InputError(path, f.name, f"expected dtype {want_dtype}, got {value.dtype}")
    if len(value.shape) != len(want_shape):
        raise InputError(path, f.name, f"expected {len(want_shape)} dimensions {_shape_text(want_shape)}, got shape {value.shape}")
    for got, want in zip(value.shape, want_shape):
        if isinstance(want, int) and got != want:
            raise InputError(path, f.name, f"expected shape {_shape_text(want_shape)}, got {value.shape}")
        if isinstance(want, str):
            if dims.setdefault(want, got) != got:
                raise InputError(path, f.name, f"expected shape {_shape_text(want_shape)} with {want} = {dims[want]}, got {value.shape}")
    if value.dtype.kind in "fc" and not np.isfinite(value).all():
        raise InputError(path, f.name, f"expected finite numbers, found {np.count_nonzero(~np.isfinite(value))} NaN or infinite")
    value.setflags(write=False)
    return value


def _shape_text(shape: tuple) -> str:
    return "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"
