"""Fuzzing `session.json`: seeded mutations of the example session's manifest (types swapped, fields removed, values
NaN / huge / negative, names with paths, steps shuffled) each either load or fail with an InputError naming the
manifest; nothing else is raised, and no file outside the temporary folder (the session's own files included) changes."""
from __future__ import annotations

import copy
import json
import math
import random
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from sandbox import EXAMPLE, copy_example, escaping, snapshot

from planner.errors import InputError
from planner.paths import ASSETS
from planner.session import MANIFEST, Session

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
    named = [("robot_spec_name",), ("task", "object", "mesh"), *(("steps", i, "files", rng.randrange(2)) for i in range(len(m["steps"])))]
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


KINDS: list[Callable[[dict, random.Random, list[str]], str]] = [_remove, _swap_type, _number, _path_name, _steps, _format_version]
WEIGHTS = [2, 3, 3, 3, 2, 1]  # format_version is checked first: changed often, it would hide the other mutations


def _mutations(base: dict, names: list[str]) -> list[tuple[str, dict]]:
    """MUTATIONS manifests, each the example's with one to three seeded mutations."""
    rng = random.Random(SEED)
    out = []
    for _ in range(MUTATIONS):
        m = copy.deepcopy(base)
        done = [rng.choices(KINDS, WEIGHTS)[0](m, rng, names) for _ in range(rng.choice([1, 1, 2, 3]))]
        out.append(("; ".join(done), m))
    return out


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
        manifest.write_text(json.dumps(mutated))  # NaN and Infinity are written as the non-standard literals Python reads back
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
