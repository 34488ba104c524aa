"""Fuzzing sessions: seeded mutations of the example session's manifest (types swapped, fields removed, values
NaN / huge / negative / of 5,000 digits, nesting hundreds deep, names with paths, steps shuffled, descriptions of any
type, meshes placed or named so no embedded mesh matches) each either load or fail with an InputError naming the
manifest; nothing else is raised, and no file outside the temporary folder (the session's own files included) changes.
The same holds for seeded mutations of the .npz entries' headers and data (dtypes, shapes declaring gigabytes, entries
added, removed or padded): an InputError naming the .npz file (or the manifest's mesh field)."""
from __future__ import annotations

import copy
import json
import math
import random
import shutil
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from sandbox import EXAMPLE, copy_example, escaping, snapshot

from planner.core.errors import InputError
from planner.core.paths import ASSETS
from planner.core.session import MANIFEST, Session

MUTATIONS = 240
SEED = 20261130
OTHER_VALUES: list[Any] = [None, True, False, 0, -1, 1.5, "x", "", [], {}, [1, 2, 3], {"a": 1}, [[]], "1"]
NUMBERS: list[Any] = [math.nan, math.inf, -math.inf, 1e308, -1e308, 2**70, -(2**70), -1, -0.5, 0, 1e-320, 10**30]

Where = tuple[Any, ...]  # keys and indices from the manifest's root to a node


def _nodes(node: Any, at: Where = ()) -> list[Where]:
    """The path (keys and indices) of every node below the root."""
    children = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
    out = []
    for key, child in children:
        out.append((*at, key))
        out += _nodes(child, (*at, key))
    return out


def _get(root: Any, at: Where) -> Any:
    for key in at:
        root = root[key]
    return root


def _put(root: Any, at: Where, value: Any) -> None:
    _get(root, at[:-1])[at[-1]] = value


def _remove(m: dict, rng: random.Random, names: list[str]) -> str:
    at = rng.choice(_nodes(m))
    del _get(m, at[:-1])[at[-1]]
    return f"removed {at}"


def _swap_type(m: dict, rng: random.Random, names: list[str]) -> str:
    at, value = rng.choice(_nodes(m)), rng.choice(OTHER_VALUES)
    _put(m, at, value)
    return f"{at} = {value!r}"


def _number(m: dict, rng: random.Random, names: list[str]) -> str:
    leaves = [at for at in _nodes(m) if type(_get(m, at)) in (int, float)]
    at, value = rng.choice(leaves), rng.choice(NUMBERS)
    _put(m, at, value)
    return f"{at} = {value!r}"


def _path_name(m: dict, rng: random.Random, names: list[str]) -> str:
    """A name with a path where a file name is read (or any string), aimed at the files outside."""
    steps = m.get("steps") if isinstance(m.get("steps"), list) else []  # an earlier mutation may have removed or retyped them
    named = [("robot_spec_name",), ("task", "object", "mesh"), *(("steps", i, "files", rng.randrange(2)) for i in range(len(steps)))]
    strings = [at for at in _nodes(m) if isinstance(_get(m, at), str)]
    at = rng.choice(named) if rng.random() < 0.7 else rng.choice(strings)
    value = rng.choice(names)
    try:
        _put(m, at, value)
    except (KeyError, IndexError, TypeError):  # an earlier mutation removed or retyped its parent
        return "skipped"
    return f"{at} = {value!r}"


def _steps(m: dict, rng: random.Random, names: list[str]) -> str:
    steps = m.get("steps")
    if not isinstance(steps, list) or len(steps) < 2:
        return "skipped"
    how = rng.choice(["duplicate", "swap", "drop", "reverse"])
    i, j = rng.sample(range(len(steps)), 2)
    if how == "duplicate":
        steps.insert(j, copy.deepcopy(steps[i]))
    elif how == "swap":
        steps[i], steps[j] = steps[j], steps[i]
    elif how == "drop":
        del steps[i]
    else:
        steps.reverse()
    return f"steps {how} {i} {j}"


def _format_version(m: dict, rng: random.Random, names: list[str]) -> str:
    value = rng.choice([True, False, "1", 1.0, 0, -1, 2, 10**40, None, [1]])
    m["format_version"] = value
    return f"format_version = {value!r}"


LONG = "@LONG@"  # written as an integer of 5,000 digits (more than Python converts; json.dumps cannot write it)


def _long_integer(m: dict, rng: random.Random, names: list[str]) -> str:
    leaves = [at for at in _nodes(m) if type(_get(m, at)) in (int, float)]
    at = rng.choice(leaves)
    _put(m, at, LONG)
    return f"{at} = 5,000 digits"


def _deep(m: dict, rng: random.Random, names: list[str]) -> str:
    """A node replaced by lists or objects nested beyond the readers' limit (up to near Python's recursion limit)."""
    at, depth = rng.choice(_nodes(m)), rng.choice([65, 300, 600, 900])
    value: Any = 1
    for k in range(depth):
        value = [value] if k % 2 else {"a": value}
    _put(m, at, value)
    return f"{at} nested {depth} deep"


def _description(m: dict, rng: random.Random, names: list[str]) -> str:
    value = rng.choice([7, None, True, [], {"a": 1}, ["text"], "x" * 100_000, "", "a fine description"])
    task = m.get("task")
    if not isinstance(task, dict):
        return "skipped"
    task["description"] = value
    return f"task.description = {_shown(value)}"


def _mesh_key(m: dict, rng: random.Random, names: list[str]) -> str:
    """The object's mesh placed another way (scale, up axis) or named otherwise: its key then names no embedded mesh."""
    obj = m.get("task", {}).get("object") if isinstance(m.get("task"), dict) else None
    if not isinstance(obj, dict):
        return "skipped"
    key, value = rng.choice([("scale", 0.001), ("scale", 0.5), ("scale", 1.0), ("up", "y"), ("up", "z"), ("up", "-x"),
                             ("mesh", "statuette.obj"), ("mesh", rng.choice(names))])
    obj[key] = value
    return f"task.object.{key} = {_shown(value)}"


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) < 40 else text[:37] + "..."


KINDS: list[Callable[[dict, random.Random, list[str]], str]] = [_remove, _swap_type, _number, _path_name, _steps, _format_version,
                                                                 _long_integer, _deep, _description, _mesh_key]
WEIGHTS = [2, 3, 3, 3, 2, 1, 1, 1, 1, 1]  # format_version is checked first: changed often, it would hide the other mutations


def _mutations(base: dict, names: list[str]) -> list[tuple[str, dict]]:
    """MUTATIONS manifests, each the example's with one to three seeded mutations."""
    rng = random.Random(SEED)
    out = []
    for _ in range(MUTATIONS):
        m = copy.deepcopy(base)
        done = [rng.choices(KINDS, WEIGHTS)[0](m, rng, names) for _ in range(rng.choice([1, 1, 2, 3]))]
        out.append(("; ".join(done), m))
    return out


@pytest.mark.slow
def test_fuzzed_manifests_load_or_raise_input_error(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    cache = tmp_path / "cache"
    monkeypatch.setenv("REGRASP_CACHE", str(cache))
    outside = tmp_path / "outside"
    outside.mkdir()
    victim = outside / "victim.txt"
    victim.write_text("keep me")
    session = copy_example(tmp_path / "session")
    manifest = session / MANIFEST
    names = ["../x", "../../outside/victim.txt", escaping(victim), str(victim), "/tmp", "a/b", "..", ".", "", "\0", "x" * 300,
             "\\..\\x", "~/x", "-rf", "con\nx"]
    base = json.loads(manifest.read_text())
    repo = {"sessions": EXAMPLE.parent, "assets": ASSETS}
    repo_before = {k: snapshot(v) for k, v in repo.items()}
    loaded = refused = 0
    for i, (what, mutated) in enumerate(_mutations(base, names)):
        # NaN and Infinity are written as the non-standard literals Python reads back
        manifest.write_text(json.dumps(mutated).replace(f'"{LONG}"', "7" * 5000))
        before = snapshot(tmp_path, skip=(cache,))
        try:
            Session.open(session)
            loaded += 1
        except InputError as exc:
            assert exc.source == str(manifest), f"mutation {i} ({what}): the error names {exc.source}, not the manifest: {exc}"
            refused += 1
        except Exception as exc:  # noqa: BLE001 - the point: nothing but an InputError may come out
            pytest.fail(f"mutation {i} ({what}) raised {type(exc).__name__}: {exc}")
        assert snapshot(tmp_path, skip=(cache,)) == before, f"mutation {i} ({what}) changed files outside the cache"
        assert victim.read_text() == "keep me"
        stray = [p for p in cache.rglob("*") if p.is_file() and p.relative_to(cache).parts[0] != "specs"]
        assert not stray, f"mutation {i} ({what}) wrote {stray} into the cache"
    assert {k: snapshot(v) for k, v in repo.items()} == repo_before
    assert loaded + refused == MUTATIONS and refused > MUTATIONS // 2 and loaded > 0, (loaded, refused)


NPZ_MUTATIONS = 60
DTYPES = ["<f8", "<f4", "<i8", "|i1", "|u1", "|b1", "<U5", "|S3", "|O", "<c16", ">f8"]


def _entry_header(rng: random.Random, shape: tuple[int, ...]) -> tuple[str, tuple[int, ...]]:
    """A dtype and shape for an entry: its own shape grown, cut or padded with huge dimensions, or another dtype."""
    how = rng.choice(["dtype", "huge", "ndim", "empty"])
    if how == "dtype":
        return rng.choice(DTYPES), shape
    if how == "huge":
        return "<f8", (rng.choice([10**6, 10**9, 10**12, 2**62]), *shape[1:])
    if how == "ndim":
        return "<f8", (*shape, 2) if rng.random() < 0.5 else shape[:-1]
    return "<f8", (0, *shape[1:])


def _mutate_npz(path: Path, rng: random.Random) -> str:
    """One entry of `path` rewritten (header and data of random size), dropped, or joined by an unknown entry."""
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    name = rng.choice(sorted(arrays))
    how = rng.choice(["header", "header", "header", "drop", "add", "pad"])
    data_size = 0
    if how == "drop":
        del arrays[name]
    with open(path, "wb") as f:
        np.savez(f, **{k: v for k, v in arrays.items() if how not in ("header", "pad") or k != name})
    if how in ("header", "pad", "add"):
        target = name if how != "add" else "unknown"
        dtype, shape = _entry_header(rng, arrays[name].shape) if how == "header" else (arrays[name].dtype.str, arrays[name].shape)
        data_size = rng.choice([0, 8, 64, 4096]) if how == "header" else arrays[name].nbytes + (4096 if how == "pad" else 0)
        with zipfile.ZipFile(path, "a") as zf, zf.open(f"{target}.npy", "w") as entry:
            np.lib.format.write_array_header_1_0(entry, {"descr": dtype, "fortran_order": False, "shape": shape})
            entry.write(arrays[name].tobytes()[:data_size].ljust(data_size, b"\0"))
        return f"{path.name}:{target} {how} {dtype} {shape} with {data_size} bytes"
    return f"{path.name}:{name} {how}"


@pytest.mark.slow
def test_fuzzed_npz_entries_load_or_raise_input_error(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("REGRASP_CACHE", str(tmp_path / "cache"))
    rng = random.Random(SEED)
    example = copy_example(tmp_path / "example")
    files = sorted(p.name for p in example.glob("*.npz"))
    refused = 0
    for i in range(NPZ_MUTATIONS):
        session = tmp_path / f"s{i}"
        shutil.copytree(example, session)
        name = rng.choice(files)
        what = _mutate_npz(session / name, rng)
        try:
            Session.open(session)
        except InputError as exc:
            assert exc.source in (str(session / name), str(session / MANIFEST)), f"mutation {i} ({what}) names {exc.source}: {exc}"
            refused += 1
        except Exception as exc:  # noqa: BLE001 - the point: nothing but an InputError may come out
            pytest.fail(f"mutation {i} ({what}) raised {type(exc).__name__}: {exc}")
        shutil.rmtree(session)
    assert refused > NPZ_MUTATIONS // 2, refused
