"""Untrusted sessions, task files, suite files and robot specs: a session's meshes are found by one key and never read
from the disk; integers too long for Python, nesting too deep for its recursion and a description that is no text are
each one InputError naming the file and the field, never a traceback."""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import trimesh
from sandbox import copy_example, forbid, one_error_line, read_manifest, regrasp, write_manifest

from planner.core.errors import InputError
from planner.core.paths import ASSETS, TASKS_DIR
from planner.core.session import MANIFEST, MESHES, Session
from planner.model.robot_spec import load_robot_spec
from planner.model.task import load_task
from planner.suite.spec import load_suite

LONG = "7" * 5000  # more digits than Python converts (4300)


@pytest.fixture
def session(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("REGRASP_CACHE", str(tmp_path / "cache"))
    return copy_example(tmp_path / "session")


def _open_error(folder: Path) -> InputError:
    with pytest.raises(InputError) as info:
        Session.open(folder)
    return info.value


def _edit(folder: Path, change: Callable[[dict[str, Any]], None]) -> None:
    manifest = read_manifest(folder)
    change(manifest)
    write_manifest(folder, manifest)


# -- mesh keys: one key, one lookup, no file ------------------------------------------------------------------------


@pytest.mark.slow
def test_a_session_of_a_scaled_mesh_reopens(tmp_path: Path) -> None:
    """A task whose mesh is in millimetres (scale = 0.001): its session opens, with the mesh it embedded."""
    mesh = trimesh.load(ASSETS / "objects" / "statuette.obj", process=False)
    mesh.apply_scale(1000.0)
    mesh.export(tmp_path / "statuette_mm.obj")
    task = (TASKS_DIR / "default.toml").read_text().replace('mesh = "statuette"', 'mesh = "statuette_mm.obj"\nscale = 0.001')
    (tmp_path / "mm.toml").write_text(task)
    run = regrasp("plan", str(tmp_path / "mm.toml"), "--out", str(tmp_path / "s"), "--until", "arms")
    assert run.returncode == 0, run.stderr
    (tmp_path / "statuette_mm.obj").unlink()  # a session needs no mesh file
    opened = Session.open(tmp_path / "s")
    assert list(opened.scene.meshes) == ["statuette_mm.obj (scale 0.001, up z)"]
    assert 0.1 < float(opened.scene.object_mesh.extents.max()) < 0.3  # metres: the embedded mesh, scaled once


def test_a_session_never_reads_a_mesh_file(session: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The embedded mesh is stored under the raw name while the task scales it: the session is refused, no file is read."""
    outside = tmp_path / "outside.obj"
    outside.write_text((ASSETS / "objects" / "statuette.obj").read_text())
    with np.load(session / MESHES) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["0_key"] = np.array(str(outside))
    np.savez(session / MESHES, **arrays)
    _edit(session, lambda m: m["task"]["object"].update(mesh=str(outside), scale=0.5))
    forbid(monkeypatch, "planner.model.object_mesh._read")
    err = _open_error(session)
    assert (err.source, err.field) == (str(session / MANIFEST), "task.object.mesh")
    assert "not embedded" in err.detail and "(scale 0.5, up z)" in err.detail


# -- integers too long, nesting too deep, descriptions that are no text ----------------------------------------------


def _long_seed(folder: Path) -> None:
    text = (folder / MANIFEST).read_text()
    (folder / MANIFEST).write_text(text.replace('"seed": 0', f'"seed": {LONG}', 1))


def _long_stat(folder: Path) -> None:
    (folder / "arms.json").write_text((folder / "arms.json").read_text().replace("{", f'{{"large": {LONG}, ', 1))


def _nested(depth: int) -> Any:
    value: Any = "deep"
    for _ in range(depth):
        value = [value]
    return value


def _manifest(change: Callable[[dict[str, Any]], None]) -> Callable[[Path], None]:
    return lambda folder: _edit(folder, change)


SESSION_CASES = {  # how the session is changed, the file and field named, what the message says
    "a 5,000-digit seed": (_long_seed, MANIFEST, "seed", "5,000 digits"),
    "a 5,000-digit integer in a step file": (_long_stat, "arms.json", "large", "5,000 digits"),
    "a description nested 600 deep": (_manifest(lambda m: m["task"].update(description=_nested(600))), MANIFEST,
                                      "task.description[0]", "nested more than 64 levels"),
    "a stat nested 900 deep": (_manifest(lambda m: m["steps"][0]["stats"].update(x=_nested(900))), MANIFEST,
                               "steps[0].stats.x[0]", "nested more than 64 levels"),
    "a description that is a number": (_manifest(lambda m: m["task"].update(description=7)), MANIFEST, "task.description",
                                       "expected a text of at most 2,000 characters, got int"),
    "a description that is an object": (_manifest(lambda m: m["task"].update(description={"a": 1})), MANIFEST,
                                         "task.description", "got dict"),
    "a description of 100,000 characters": (_manifest(lambda m: m["task"].update(description="x" * 100_000)), MANIFEST,
                                            "task.description", "got 100,000 characters"),
}


@pytest.mark.parametrize("case", list(SESSION_CASES))
def test_a_bad_value_in_a_session_is_one_error_naming_file_and_field(session: Path, case: str) -> None:
    change, name, field, phrase = SESSION_CASES[case]
    change(session)
    err = _open_error(session)
    assert err.source == str(session / name) and err.field is not None and err.field.startswith(field), err
    assert phrase in err.detail, err.detail


def test_a_long_integer_in_set_is_one_line() -> None:
    run = regrasp("plan", "default", "--out", "/nonexistent/never", "--set", f"arms.tolerance={LONG}")
    assert run.returncode == 2
    line = one_error_line(run.stderr)
    assert "--set" in line and "'arms.tolerance'" in line and "5,000 digits" in line, line


def _task_file(folder: Path, extra: str) -> Path:
    path = folder / "task.toml"
    path.write_text(extra + (TASKS_DIR / "default.toml").read_text())
    return path


def _suite_file(folder: Path, extra: str) -> Path:
    path = folder / "suite.toml"
    path.write_text(extra + 'name = "s"\ntask = "default"\ntasks = 1\n')
    return path


def _spec_file(folder: Path, extra: str) -> Path:
    path = folder / "spec.toml"
    path.write_text(extra + (ASSETS / "robots" / "alex_allegro.toml").read_text())
    return path


READERS = {"task": (_task_file, load_task), "suite": (_suite_file, load_suite), "robot spec": (_spec_file, load_robot_spec)}
TOML_CASES = {  # the first lines of the file, the field named (None: the file as a whole), what the message says
    "a 5,000-digit integer": (f"x = {LONG}\n", "x (line 1)", "more than 4300 digits"),
    "a 200-digit integer": (f"x = {'9' * 200}\n", "x", "200 digits"),
    "nested 20,000 deep": (f"x = {'[' * 20_000}{']' * 20_000}\n", None, "nested deeper than Python can parse"),
    "nested 100 deep": (f"x = {'[' * 100}{']' * 100}\n", "x[0]", "nested more than 64 levels"),
}


@pytest.mark.parametrize("reader", list(READERS))
@pytest.mark.parametrize("case", list(TOML_CASES))
def test_a_toml_file_too_deep_or_with_a_long_integer_is_one_error(tmp_path: Path, reader: str, case: str) -> None:
    write, load = READERS[reader]
    extra, field, phrase = TOML_CASES[case]
    path = write(tmp_path, extra)
    with pytest.raises(InputError) as info:
        load(path)
    err = info.value
    assert err.source == str(path), err
    assert (err.field is None) if field is None else (err.field or "").startswith(field), err
    assert phrase in err.detail, err.detail


def test_the_command_line_names_a_long_integer_in_a_task_file(tmp_path: Path) -> None:
    path = _task_file(tmp_path, f"x = {LONG}\n")
    run = regrasp("check", str(path))
    assert run.returncode == 2
    line = one_error_line(run.stderr)
    assert str(path) in line and "'x (line 1)'" in line, line

