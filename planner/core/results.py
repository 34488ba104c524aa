"""Step results: frozen dataclasses that write themselves into a session and read themselves back.

Fields declared with `array(dtype, shape)` go to the step's `.npz` (shape entries: an int, or a
name like "n" shared between fields (the session fixes "nq" to the robot's DoF), or None for any); every other field must be JSON-able
(numbers, strings, bools, lists, dicts) and goes to the step's `.json`. Loading checks every
array's dtype and shape and every JSON field's presence, with errors naming the file and field; a JSON field declared
with a default was added later: it is written only when it differs from its default, and a file without it (written
before it) loads with the default.
"""
from __future__ import annotations

import contextlib
import dataclasses
import errno
import json
import os
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from planner.core.errors import InputError, RegraspError
from planner.core.npz import Budget, npz_bytes, read_npz

R = TypeVar("R")


def array(dtype: str, shape: tuple[int | str | None, ...], optional: bool = False) -> Any:
    """Declare a numpy-array field of a result: saved to the .npz and checked on load. `optional`: a field added after
    results were saved without it, empty (no rows) by default; left out of the .npz while empty, and empty when a file
    does not hold it."""
    if optional:
        empty = np.zeros((0,) * len(shape), dtype=dtype)
        empty.setflags(write=False)
        return dataclasses.field(default_factory=lambda: empty, metadata={"dtype": np.dtype(dtype).str, "shape": shape,
                                                                         "optional": True})
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


class FrozenDict(dict):
    """A dict no one can change: a result's JSON object (still a dict to json and isinstance, copied and pickled as one)."""

    def _refuse(self, *args: Any, **kwargs: Any) -> None:
        raise TypeError(f"{type(self).__name__} is read-only")

    __setitem__ = __delitem__ = __ior__ = clear = pop = popitem = setdefault = update = _refuse

    def __reduce__(self) -> tuple:
        return type(self), (dict(self),)


def frozen_json(value: Any) -> Any:
    """JSON-like data made immutable all the way down: lists (and tuples) as tuples, dicts as FrozenDicts, arrays read-only."""
    if isinstance(value, np.ndarray):
        return frozen(value)
    if isinstance(value, (list, tuple)):
        return tuple(frozen_json(v) for v in value)
    if isinstance(value, Mapping):
        return FrozenDict((k, frozen_json(v)) for k, v in value.items())
    return value


def read_only(result: R) -> R:
    """A copy of `result` whose JSON fields are immutable (see frozen_json), its arrays (the same) made read-only:
    results are immutable once built, like loaded ones."""
    rest = {}
    for f in dataclasses.fields(result):
        if _is_array(f):
            getattr(result, f.name).setflags(write=False)
        else:
            rest[f.name] = frozen_json(getattr(result, f.name))
    return dataclasses.replace(result, **rest)


def save_result(result: Any, folder: Path, stem: str) -> list[str]:
    """Write a result as `<stem>.npz` (arrays) and `<stem>.json` (the rest); returns the file names."""
    arrays, rest = {}, {}
    for f in dataclasses.fields(result):
        value = getattr(result, f.name)
        if _is_array(f):
            if f.metadata.get("optional") and not value.size:
                continue  # as older files have it
            arrays[f.name] = np.ascontiguousarray(value, dtype=np.dtype(f.metadata["dtype"]))
        elif f.default is dataclasses.MISSING or value != f.default:  # a field added later, at its default: as older files have it
            rest[f.name] = value
    atomic_write_bytes(folder / f"{stem}.npz", npz_bytes(arrays))
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


def not_a_link(path: Path, why: str) -> Path:
    """`path` unless it is a symbolic link (read or written through, it would reach outside its folder): an InputError
    naming it and `why` it must be plain."""
    if path.is_symlink():
        raise InputError(path, None, f"a symbolic link: {why}")
    return path


def regular_file(path: Path, missing: str) -> Path:
    """`path` if it is a regular file (not a link, a folder or a device); else an InputError (`missing` says why it should be there)."""
    not_a_link(path, "a session's files must be plain files inside its folder")
    if not path.exists():
        raise InputError(path, None, f"missing: {missing}")
    if not path.is_file():
        raise InputError(path, None, "not a regular file")
    return path


MAX_DEPTH = 64  # lists and objects inside each other: deeper is no data regrasp writes, and Python's recursion ends near 1000
MAX_INT_DIGITS = 100  # Python refuses to convert integers of more than 4300 digits; no field regrasp reads needs 100


class _LongInt(str):
    """An integer literal too long to convert, kept as its text so that `check_nesting` can name the field holding it."""


def _int(text: str) -> int | _LongInt:
    return int(text) if len(text.lstrip("-")) <= MAX_INT_DIGITS else _LongInt(text)


def parse_json(text: str) -> Any:
    """JSON text as Python data, integers too long to convert kept as text for `check_nesting` to refuse by field."""
    return json.loads(text, parse_int=_int)


def check_nesting(data: Any, source: str | Path, root: str = "") -> None:
    """Refuse data read from a file that is nested more than MAX_DEPTH deep or holds an integer of more than MAX_INT_DIGITS
    digits (Python's recursion and integer conversion would end in a traceback), naming the field."""
    stack = [(data, root, 0)]
    while stack:
        node, field, depth = stack.pop()
        if depth > MAX_DEPTH:
            shown = field if len(field) <= 80 else field[:77] + "..."
            raise InputError(source, shown or None, f"nested more than {MAX_DEPTH} levels deep; expected plain values")
        digits = len(node.lstrip("-")) if isinstance(node, _LongInt) else \
            len(str(abs(node))) if type(node) is int and node.bit_length() > 3 * MAX_INT_DIGITS else 0
        if digits > MAX_INT_DIGITS:
            raise InputError(source, field or None, f"an integer of {digits:,} digits; expected at most {MAX_INT_DIGITS} digits")
        if isinstance(node, dict):
            stack.extend((v, f"{field}.{k}" if field else str(k), depth + 1) for k, v in node.items())
        elif isinstance(node, list):
            stack.extend((v, f"{field}[{i}]", depth + 1) for i, v in enumerate(node))


def read_json_object(path: Path) -> dict[str, Any]:
    """A JSON file that must hold an object (nested at most MAX_DEPTH deep, integers of at most MAX_INT_DIGITS digits);
    anything else is an InputError naming the file (and the field)."""
    try:
        data = parse_json(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError, RecursionError) as exc:
        raise InputError(path, None, f"not valid JSON ({type(exc).__name__}: {exc})") from exc
    except OSError as exc:
        raise InputError(path, None, f"cannot be read ({os.strerror(exc.errno) if exc.errno else exc})") from exc
    if not isinstance(data, dict):
        raise InputError(path, None, "expected a JSON object")
    check_nesting(data, path)
    return data


def load_result(cls: type[R], folder: Path, stem: str, dims: dict[str, int] | None = None, budget: Budget | None = None) -> R:
    """Read a result written by `save_result`, checking every field; errors name the file and field.

    Only the arrays `cls` declares are read, each header checked before its data (see npz.py).
    `dims` fixes named dimensions known from the scene (e.g. nq, the robot's DoF); `budget` is shared by a session's files."""
    npz_path, json_path = folder / f"{stem}.npz", folder / f"{stem}.json"
    for p in (npz_path, json_path):
        regular_file(p, "the session lists this step as finished but its file is gone")
    rest = read_json_object(json_path)
    fields = dataclasses.fields(cls)
    declared = {f.name: (np.dtype(f.metadata["dtype"]), f.metadata["shape"]) for f in fields if _is_array(f)}
    optional = {f.name for f in fields if _is_array(f) and f.metadata.get("optional")}
    arrays = read_npz(npz_path, declared, dict(dims or {}), budget, optional)
    values: dict[str, Any] = {}
    for f in fields:
        if _is_array(f):
            if f.name in arrays:
                values[f.name] = _finite(arrays[f.name], npz_path, f.name)
        else:
            if f.name in rest:
                values[f.name] = frozen_json(rest[f.name])
            elif f.default is dataclasses.MISSING:
                raise InputError(json_path, f.name, "missing field")
    unknown = set(rest) - set(values)
    if unknown:
        raise InputError(json_path, sorted(unknown)[0], f"unknown field (this version of {cls.__name__} does not have it)")
    return cls(**values)


def _finite(value: np.ndarray, path: Path, field: str) -> np.ndarray:
    """`value` made read-only, once its floats are checked to be finite."""
    if value.dtype.kind in "fc" and not np.isfinite(value).all():
        raise InputError(path, field, f"expected finite numbers, found {np.count_nonzero(~np.isfinite(value))} NaN or infinite")
    value.setflags(write=False)
    return value
