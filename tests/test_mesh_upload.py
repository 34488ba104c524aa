"""Meshes uploaded from the browser (workbench/mesh_upload.py, and the client guard's size limit): refused when too large
(by the declared size, before any byte is kept), of a format no mesh is read from, or no closed mesh, with the text
`regrasp check` gives for the same file in a task; stored under a plain name inside the uploads folder, never replacing
another upload."""
from __future__ import annotations

import io
from pathlib import Path

import pytest
import trimesh
import viser
from viser import _messages

from planner.core.errors import InputError
from planner.model.task import load_task
from planner.model.task_edit import with_object_mesh
from planner.model.task_file import write_task
from workbench import mesh_upload
from workbench.client_guard import ClientGuard
from workbench.mesh_upload import store_upload, upload_name
from workbench.screenshot import free_port


def _stl(extents: tuple[float, float, float]) -> bytes:
    box = trimesh.creation.box(extents=extents)
    out = io.BytesIO()
    box.export(out, file_type="stl")
    return out.getvalue()


FLAT_OBJ = b"v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nv 0.1 0.1 0\nf 1 2 3\nf 2 4 3\n"  # a square: no volume


def _check_message(tmp_path: Path, name: str, content: bytes) -> str:
    """What loading a task naming the file says (the message `regrasp check` prints), after the file's path."""
    path = tmp_path / "cli" / name
    path.parent.mkdir(exist_ok=True)
    path.write_bytes(content)
    scene = load_task("default")
    task = write_task(with_object_mesh(scene.task, str(path)), scene.source, tmp_path / "cli" / "task.toml", overwrite=True)
    with pytest.raises(InputError) as caught:
        load_task(task)
    return str(caught.value).split(f"{path}: ", 1)[1]


@pytest.mark.parametrize(("name", "content"), [("flat.obj", FLAT_OBJ), ("noise.stl", b"solid x\n\x00\x01garbage"),
                                               ("huge.stl", _stl((3.0, 3.0, 3.0))), ("empty.ply", b"")])
def test_a_bad_mesh_is_refused_with_the_message_check_gives(tmp_path: Path, name: str, content: bytes) -> None:
    expected = _check_message(tmp_path, name, content)
    with pytest.raises(InputError) as caught:
        store_upload(name, content, tmp_path / "uploads")
    assert str(caught.value) == f"{name}: the object mesh {expected}"
    assert not any((tmp_path / "uploads").iterdir())  # nothing kept


@pytest.mark.parametrize("name", ["mesh.exe", "mesh", "mesh.obj.sh", "/etc/passwd"])
def test_a_format_no_mesh_is_read_from_is_refused_before_anything_is_written(tmp_path: Path, name: str) -> None:
    with pytest.raises(InputError, match="unsupported mesh format .*expected one of .obj, .stl, .ply, .off, .glb"):
        store_upload(name, _stl((0.05, 0.05, 0.1)), tmp_path / "uploads")
    assert not (tmp_path / "uploads").exists()


def test_an_oversized_upload_is_refused_by_its_size(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    content = _stl((0.05, 0.05, 0.1))
    monkeypatch.setattr(mesh_upload, "MAX_UPLOAD_BYTES", len(content) - 1)
    with pytest.raises(InputError, match=f"is {len(content):,} bytes, more than the {len(content) - 1:,} bytes"):
        store_upload("box.stl", content, tmp_path / "uploads")
    assert not (tmp_path / "uploads").exists()


@pytest.mark.parametrize(("given", "kept"), [("../../evil.stl", "evil.stl"), ("..\\..\\evil.STL", "evil.stl"),
                                             (".hidden.stl", "hidden.stl"), ("a b$c.stl", "a_b_c.stl"),
                                             ("....stl", "mesh.stl"), ("x/../../y.stl", "y.stl"),
                                             ("\x00\n.stl", "mesh.stl"), ("ünï.stl", "n.stl")])
def test_a_name_never_leaves_the_uploads_folder(tmp_path: Path, given: str, kept: str) -> None:
    assert upload_name(given) == kept
    folder = tmp_path / "uploads"
    path = store_upload(given, _stl((0.05, 0.05, 0.1)), folder)
    assert path == folder / kept and [p.name for p in folder.iterdir()] == [kept]


def test_an_upload_never_replaces_another(tmp_path: Path) -> None:
    folder = tmp_path / "uploads"
    first = store_upload("box.stl", _stl((0.05, 0.05, 0.1)), folder)
    second = store_upload("box.stl", _stl((0.06, 0.05, 0.1)), folder)
    again = store_upload("box.stl", _stl((0.05, 0.05, 0.1)), folder)
    assert (first.name, second.name, again) == ("box.stl", "box-2.stl", first)
    assert trimesh.load(first).extents == pytest.approx([0.05, 0.05, 0.1])


def test_the_guard_refuses_an_oversized_upload_before_its_bytes() -> None:
    """The declared size over the limit, or more parts than bytes allow: dropped at the start; parts past the declared
    size: dropped."""
    server = viser.ViserServer(host="127.0.0.1", port=free_port(), verbose=False)
    try:
        guard = ClientGuard(server, "127.0.0.1")

        def start(size: int, parts: int, transfer: str = "t") -> bool:
            message = _messages.FileTransferStartUpload("button", transfer, "box.stl", "", parts, size)
            return guard._upload_allowed(1, message)

        def part(content: bytes, transfer: str = "t", client: int = 1) -> bool:
            return guard._upload_allowed(client, _messages.FileTransferPart("button", transfer, 0, content))

        assert not start(mesh_upload.MAX_UPLOAD_BYTES + 1, 65)
        assert not start(1000, 1000)  # 1000 parts of one byte
        assert not part(b"x" * 10)  # a part of a transfer never started
        assert start(4000, 2)
        assert not part(b"x" * 10, client=2)  # another tab's part
        assert part(b"x" * 2400) and not part(b"x" * 2400)  # 4800 bytes of 4000 declared
        assert not part(b"x")  # nor anything after
        assert start(4000, 2, "u") and part(b"x" * 2000, "u") and part(b"x" * 2000, "u")
    finally:
        server.stop()
