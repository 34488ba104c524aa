"""Sessions from strangers: names read from a session never reach outside its folder or the cache, and a bad manifest
is one InputError naming the file and the field, raised before anything is written."""
from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from sandbox import (
    copy_example,
    escaping,
    one_error_line,
    read_manifest,
    regrasp,
    snapshot,
    write_manifest,
)

from planner.core.errors import InputError
from planner.core.session import MANIFEST, MESHES, Session

SHARED_CACHE = os.environ["REGRASP_CACHE"]  # the suite's cache (conftest), warm: `plan` runs use it


@dataclass(frozen=True)
class Sandbox:
    """A session copy, a private user cache and a folder of files that no session may touch, side by side."""

    root: Path
    session: Path
    cache: Path
    outside: Path

    def others(self) -> dict[str, str]:
        """Everything under the root but the session and the cache (must never change)."""
        return snapshot(self.root, skip=(self.session, self.cache))

    def manifest_path(self) -> str:
        return str(self.session / MANIFEST)


@pytest.fixture
def sandbox(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Sandbox:
    cache = tmp_path / "cache"
    cache.mkdir()
    monkeypatch.setenv("REGRASP_CACHE", str(cache))
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "victim.txt").write_text("keep me")
    return Sandbox(tmp_path, copy_example(tmp_path / "session"), cache, outside)


def _edit(folder: Path, change: Callable[[dict[str, Any]], None]) -> None:
    manifest = read_manifest(folder)
    change(manifest)
    write_manifest(folder, manifest)


def _open_error(folder: Path) -> InputError:
    with pytest.raises(InputError) as info:
        Session.open(folder)
    return info.value


# -- 1. the robot spec's name: never a path --------------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["relative", "absolute", "separator", "dotdot", "number"])
def test_spec_name_never_writes_outside_the_cache(sandbox: Sandbox, kind: str) -> None:
    target = sandbox.outside / "victim.txt"
    name = {"relative": escaping(target), "absolute": str(target), "separator": "sub/alex.toml", "dotdot": "..", "number": 7}[kind]
    before = sandbox.others()

    def change(m: dict[str, Any]) -> None:
        m["robot_spec_name"], m["robot_spec"] = name, "pwned = true\n"
    _edit(sandbox.session, change)
    err = _open_error(sandbox.session)
    assert err.source == sandbox.manifest_path() and err.field == "robot_spec_name"
    assert "file name" in err.detail
    assert sandbox.others() == before and target.read_text() == "keep me"
    assert list(sandbox.cache.iterdir()) == [], "the manifest must be refused before anything is written to the cache"


@pytest.mark.parametrize("command", [("replay", "{s}", "--port", "1"), ("export", "{s}", "--html", "{o}/out.html"),
                                     ("plan", "default", "--out", "{s}", "--resume")], ids=["replay", "export", "resume"])
def test_every_entry_point_refuses_a_spec_name_with_a_path(sandbox: Sandbox, command: tuple[str, ...]) -> None:
    target = sandbox.outside / "victim.txt"
    _edit(sandbox.session, lambda m: m.update(robot_spec_name=str(target), robot_spec="pwned = true\n"))
    before = sandbox.others()
    run = regrasp(*(a.format(s=sandbox.session, o=sandbox.outside) for a in command))
    assert run.returncode == 2
    line = one_error_line(run.stderr)
    assert sandbox.manifest_path() in line and "robot_spec_name" in line
    assert sandbox.others() == before and target.read_text() == "keep me"


def test_workbench_refuses_a_spec_name_with_a_path_before_serving(sandbox: Sandbox) -> None:
    from workbench.app import Workbench

    target = sandbox.outside / "victim.txt"
    _edit(sandbox.session, lambda m: m.update(robot_spec_name=escaping(target), robot_spec="pwned = true\n"))
    before = sandbox.others()
    with pytest.raises(InputError, match="robot_spec_name"):
        Workbench(None, "127.0.0.1", 1, session=sandbox.session)
    assert sandbox.others() == before and target.read_text() == "keep me"


# -- 2. the files a step lists: never deleted outside the session ----------------------------------------------------


@pytest.mark.slow
def test_plan_force_deletes_only_the_sessions_own_files(sandbox: Sandbox) -> None:
    victims = [sandbox.outside / "victim.txt", sandbox.outside / "other.txt"]
    victims[1].write_text("keep me too")

    def change(m: dict[str, Any]) -> None:
        m["steps"][0]["files"] = [escaping(victims[0]), str(victims[1])]
    _edit(sandbox.session, change)
    before = sandbox.others()
    run = regrasp("plan", "default", "--out", str(sandbox.session), "--force", "--until", "arms", REGRASP_CACHE=SHARED_CACHE)
    assert run.returncode == 0, run.stderr
    assert sandbox.others() == before and all(v.exists() for v in victims)
    assert Session.open(sandbox.session).finished() == ["arms"]


def test_resume_refuses_step_files_with_a_path(sandbox: Sandbox) -> None:
    _edit(sandbox.session, lambda m: m["steps"][0].update(files=["../arms.npz", "arms.json"]))
    before = sandbox.others()
    run = regrasp("plan", "default", "--out", str(sandbox.session), "--resume", REGRASP_CACHE=SHARED_CACHE)
    assert run.returncode == 2
    line = one_error_line(run.stderr)
    assert sandbox.manifest_path() in line and "steps[0].files[0]" in line and "plain file name" in line
    assert sandbox.others() == before


# -- 6. wrong types, order and values in the manifest ----------------------------------------------------------------


def _set(*path: Any, value: Any) -> Callable[[dict[str, Any]], None]:
    def change(m: dict[str, Any]) -> None:
        node = m
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] = value
    return change


def _steps(edit: Callable[[list], None]) -> Callable[[dict[str, Any]], None]:
    return lambda m: edit(m["steps"])


MANIFEST_CASES = {
    "stats not an object": (_set("steps", 0, "stats", value=[1, 2]), "steps[0].stats", "expected an object of statistics"),
    "seconds a string": (_set("steps", 1, "seconds", value="fast"), "steps[1].seconds", "expected a number of seconds"),
    "seconds NaN": (_set("steps", 1, "seconds", value=math.nan), "steps[1].seconds", "finite"),
    "seed a string": (_set("seed", value="0"), "seed", "expected an integer seed"),
    "seed negative": (_set("seed", value=-1), "seed", "from 0 to 2**64 - 1"),
    "seed huge": (_set("seed", value=2**80), "seed", "from 0 to 2**64 - 1"),
    "step seed a bool": (_set("steps", 0, "seed", value=True), "steps[0].seed", "expected an integer seed"),
    "robot_spec a number": (_set("robot_spec", value=3.5), "robot_spec", "expected the robot spec's text"),
    "robot_spec_name a number": (_set("robot_spec_name", value=12), "robot_spec_name", "expected a file name"),
    "format_version true": (_set("format_version", value=True), "format_version", "expected an integer format version"),
    "format_version a string": (_set("format_version", value="1"), "format_version", "expected an integer format version"),
    "format_version zero": (_set("format_version", value=0), "format_version", "from 1 to"),
    "duplicated step": (_steps(lambda s: s.insert(1, dict(s[0]))), "steps[1].name", "listed twice"),
    "steps out of order": (_steps(lambda s: s.insert(1, s.pop(2))), "steps[2].name", "pipeline order"),
    "a step before what it needs": (_steps(lambda s: s.pop(0)), "steps[0].name", "needs 'arms'"),
    "unknown step": (_set("steps", 0, "name", value="teleport"), "steps[0].name", "no step 'teleport'"),
    "step not an object": (_set("steps", 0, value="arms"), "steps[0]", "expected an object"),
    "step field missing": (lambda m: m["steps"][0].pop("files"), "steps[0].files", "missing field"),
    "files with a separator": (_set("steps", 0, "files", 0, value="sub/arms.npz"), "steps[0].files[0]", "plain file name"),
    "files of another step": (_set("steps", 0, "files", value=["roadmap.npz", "roadmap.json"]), "steps[0].files", "expected ['arms.npz'"),
    "param of the wrong type": (_set("steps", 0, "params", "seeds", value="many"), "steps[0].params", "expects int"),
    "param NaN": (_set("steps", 0, "params", "tolerance", value=math.nan), "steps[0].params.tolerance", "finite"),
    "stage seconds negative": (_set("steps", 3, "stage_seconds", 0, value=-2.0), "steps[3].stage_seconds[0]", ">= 0"),
    "cached not a flag": (_set("steps", 6, "cached", value="yes"), "steps[6].cached", "expected true or false"),
    "versions not strings": (_set("versions", "numpy", value=2), "versions.numpy", "expected a version string"),
    "steps not a list": (_set("steps", value={"arms": {}}), "steps", "expected a list"),
    "task not an object": (_set("task", value="default.toml"), "task", "expected the task as a JSON object"),
    "unknown field": (_set("hook", value="rm -rf ~"), "hook", "unknown field"),
    "field removed": (lambda m: m.pop("versions"), "versions", "missing field"),
}


@pytest.mark.parametrize("case", list(MANIFEST_CASES))
def test_bad_manifest_is_one_error_naming_file_and_field(sandbox: Sandbox, case: str) -> None:
    change, field, phrase = MANIFEST_CASES[case]
    _edit(sandbox.session, change)
    before = snapshot(sandbox.root)
    err = _open_error(sandbox.session)
    assert (err.source, err.field) == (sandbox.manifest_path(), field)
    assert phrase in err.detail, err.detail
    assert "newer" not in err.detail
    assert snapshot(sandbox.root) == before, "a refused session must leave every file (cache included) as it was"


# -- 6. bad step and mesh files --------------------------------------------------------------------------------------


def _rewrite_npz(path: Path, change: Callable[[dict[str, np.ndarray]], None]) -> None:
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    change(arrays)
    with open(path, "wb") as f:
        np.savez(f, **arrays)


def _nan_q(arrays: dict[str, np.ndarray]) -> None:
    arrays["q_pick"] = arrays["q_pick"].copy()
    arrays["q_pick"][3] = np.nan


def _faces_out_of_range(arrays: dict[str, np.ndarray]) -> None:
    arrays["0_faces"] = arrays["0_faces"] + len(arrays["0_vertices"])


FILE_CASES = {
    "truncated task_meshes.npz": (MESHES, lambda p: p.write_bytes(p.read_bytes()[:1000]), None, "truncated or corrupt"),
    "task_meshes faces out of range": (MESHES, lambda p: _rewrite_npz(p, _faces_out_of_range), "0_faces", "integer indices below"),
    "NaN in a configuration": ("arms.npz", lambda p: _rewrite_npz(p, _nan_q), "q_pick", "expected finite numbers"),
    "step file a symbolic link": ("arms.json", None, None, "symbolic link"),
}


@pytest.mark.parametrize("case", list(FILE_CASES))
def test_bad_session_file_is_one_error_naming_it(sandbox: Sandbox, case: str) -> None:
    name, damage, field, phrase = FILE_CASES[case]
    path = sandbox.session / name
    if damage is None:  # a link to a file outside: its content must not be read (or later copied into a saved session)
        (sandbox.outside / name).write_bytes(path.read_bytes())
        path.unlink()
        path.symlink_to(sandbox.outside / name)
    else:
        damage(path)
    before = sandbox.others()
    err = _open_error(sandbox.session)
    assert (err.source, err.field) == (str(path), field)
    assert phrase in err.detail, err.detail
    assert sandbox.others() == before
