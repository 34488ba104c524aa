"""Sessions built to exhaust memory: an embedded mesh far over the face limit, .npz headers declaring 100 GB, an entry no
step declares that decompresses to gigabytes. `regrasp export` runs under a 2 GB address-space limit (prlimit --as) and
ends in one line naming the file, the field and the limit, or (the undeclared entry, never read) exports the session."""
from __future__ import annotations

import os
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from sandbox import copy_example, one_error_line, regrasp

from planner.core.errors import InputError
from planner.core.npz import MAX_ARRAY_BYTES
from planner.core.session import MESHES, Session
from planner.model.object_mesh import MAX_FACES

MEMORY = 2 * 2**30
LIMITED = ("prlimit", f"--as={MEMORY}")  # the address space of the export process: above it an allocation fails


def _entries(path: Path) -> dict[str, np.ndarray]:
    with np.load(path) as z:
        return {k: z[k] for k in z.files}


def _rewrite(path: Path, change: Callable[[dict[str, np.ndarray]], None]) -> None:
    arrays = _entries(path)
    change(arrays)
    with open(path, "wb") as f:
        np.savez_compressed(f, **arrays)


def _header_only(path: Path, name: str, shape: tuple[int, ...], dtype: str = "<f8") -> None:
    """Replace entry `name` of an .npz by an .npy header declaring `shape` followed by 64 bytes of data."""
    arrays = _entries(path)
    arrays.pop(name)
    with open(path, "wb") as f:
        np.savez(f, **arrays)
    header = {"descr": dtype, "fortran_order": False, "shape": shape}
    with zipfile.ZipFile(path, "a", compression=zipfile.ZIP_DEFLATED) as zf, zf.open(f"{name}.npy", "w") as entry:
        np.lib.format.write_array_header_1_0(entry, header)
        entry.write(bytes(64))


def _export(session: Path, tmp: Path) -> tuple[int, str]:
    run = regrasp("export", str(session), "--html", str(tmp / "out.html"), prefix=LIMITED, timeout=900)
    return run.returncode, run.stderr


@pytest.fixture
def session(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("REGRASP_CACHE", str(tmp_path / "cache"))
    return copy_example(tmp_path / "session")


def _many_faces(arrays: dict[str, np.ndarray]) -> None:
    arrays["0_faces"] = np.tile(arrays["0_faces"], (2_000_000 // len(arrays["0_faces"]) + 1, 1))[:2_000_000]


BOMBS = {  # file, how it is built, the field named, the limit named
    "embedded mesh of 2,000,000 faces": (MESHES, lambda p: _rewrite(p, _many_faces), "0_faces", f"{MAX_FACES:,}"),
    "embedded vertices declaring 240 GB": (MESHES, lambda p: _header_only(p, "0_vertices", (10**10, 3)), "0_vertices",
                                           f"{3 * MAX_FACES:,}"),
    "embedded faces declaring 240 GB": (MESHES, lambda p: _header_only(p, "0_faces", (10**10, 3), "<i8"), "0_faces",
                                        f"{MAX_FACES:,}"),
    "step array declaring 100 GB": ("motion.npz", lambda p: _header_only(p, "t", (12_500_000_000,)), "t",
                                    f"{MAX_ARRAY_BYTES:,}"),
}


@pytest.mark.slow
@pytest.mark.parametrize("case", list(BOMBS))
def test_a_bomb_is_one_line_naming_file_field_and_limit_within_2_gb(session: Path, tmp_path: Path, case: str) -> None:
    name, build, field, limit = BOMBS[case]
    build(session / name)
    code, stderr = _export(session, tmp_path)
    assert code == 2, stderr
    line = one_error_line(stderr)
    assert str(session / name) in line and f"'{field}'" in line and limit in line, line
    assert not (tmp_path / "out.html").exists()


@pytest.mark.slow
def test_an_entry_no_step_declares_is_never_decompressed(session: Path, tmp_path: Path) -> None:
    """A 2.5 GB entry (12 MB compressed) beside a step's arrays: the session exports within 2 GB, never reading it."""
    size, chunk = 5 * 2**29, bytes(2**24)
    with zipfile.ZipFile(session / "arms.npz", "a", compression=zipfile.ZIP_DEFLATED, compresslevel=1) as zf, \
            zf.open("padding.npy", "w", force_zip64=True) as entry:
        np.lib.format.write_array_header_1_0(entry, {"descr": "|u1", "fortran_order": False, "shape": (size,)})
        for _ in range(size // len(chunk)):
            entry.write(chunk)
    assert os.path.getsize(session / "arms.npz") < 16 * 2**20
    code, stderr = _export(session, tmp_path)
    assert code == 0, stderr
    assert (tmp_path / "out.html").stat().st_size > 0


# -- the checks a mesh file passes, on an embedded mesh (in process: no memory at stake) -----------------------------


def _open_error(folder: Path) -> InputError:
    with pytest.raises(InputError) as info:
        Session.open(folder)
    return info.value


def _scaled(arrays: dict[str, np.ndarray]) -> None:
    arrays["0_vertices"] = arrays["0_vertices"] * 100.0


def _open(arrays: dict[str, np.ndarray]) -> None:
    arrays["0_faces"] = arrays["0_faces"][: len(arrays["0_faces"]) // 2]


def _nan(arrays: dict[str, np.ndarray]) -> None:
    arrays["0_vertices"] = arrays["0_vertices"].copy()
    arrays["0_vertices"][5, 1] = np.nan


def _strings(arrays: dict[str, np.ndarray]) -> None:
    arrays["0_faces"] = arrays["0_faces"].astype(str)


def _float_faces(arrays: dict[str, np.ndarray]) -> None:
    arrays["0_faces"] = arrays["0_faces"].astype(np.float64)


MESH_CASES = {  # how the embedded mesh is changed, the file and field named, what the message says
    "open (half its faces)": (_open, "session.json", "task.object.mesh", "not a closed volume"),
    "a hundred times too large": (_scaled, "session.json", "task.object.mesh", "absurd size for an object"),
    "a NaN vertex": (_nan, MESHES, "0_vertices", "finite"),
    "faces stored as strings": (_strings, MESHES, "0_faces", "expected dtype int64"),
    "faces stored as floats": (_float_faces, MESHES, "0_faces", "expected dtype int64"),
}


@pytest.mark.parametrize("case", list(MESH_CASES))
def test_an_embedded_mesh_passes_the_checks_a_mesh_file_passes(session: Path, case: str) -> None:
    change, name, field, phrase = MESH_CASES[case]
    _rewrite(session / MESHES, change)
    err = _open_error(session)
    assert (err.source, err.field) == (str(session / name), field)
    assert phrase in err.detail, err.detail


def test_an_entry_larger_than_its_header_says_is_refused(session: Path) -> None:
    """The zip entry's uncompressed size must be the header's plus its declared data: no hidden payload."""
    arrays = _entries(session / "arms.npz")
    with open(session / "arms.npz", "wb") as f:
        np.savez(f, q_place=arrays["q_place"])
    with zipfile.ZipFile(session / "arms.npz", "a") as zf, zf.open("q_pick.npy", "w") as entry:
        np.lib.format.write_array(entry, arrays["q_pick"])
        entry.write(bytes(4096))
    err = _open_error(session)
    assert (err.source, err.field) == (str(session / "arms.npz"), "q_pick")
    assert "truncated or corrupt" in err.detail


def test_the_arrays_of_all_a_sessions_files_share_one_budget(session: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Files each within the limit cannot add up to a bomb: with a budget between the example's largest file of
    arrays and all of them, they are refused at the file that crosses it, naming the limit."""
    sizes = {p.name: sum(i.file_size for i in zipfile.ZipFile(p).infolist()) for p in session.glob("*.npz")}
    limit = (max(sizes.values()) + sum(sizes.values())) // 2
    assert max(sizes.values()) < limit < sum(sizes.values())
    monkeypatch.setattr("planner.core.npz.MAX_READ_BYTES", limit)
    err = _open_error(session)
    assert err.source.endswith(".npz") and Path(err.source).parent == session
    assert f"{limit:,} bytes allowed for one session" in err.detail, err.detail


def test_an_entry_of_an_unsupported_compression_method_is_one_line(tmp_path: Path) -> None:
    """A crafted .npz whose entry names a compression method zipfile lacks (99, AES) is bad input, not a traceback."""
    from planner.core.errors import InputError
    from planner.core.npz import read_npz

    path = tmp_path / "crafted.npz"
    np.savez(path, q=np.zeros(3))
    data = bytearray(path.read_bytes())
    for signature, offset in ((b"PK\x03\x04", 8), (b"PK\x01\x02", 10)):  # local header, central directory: method field
        at = data.find(signature)
        data[at + offset: at + offset + 2] = (99).to_bytes(2, "little")
    path.write_bytes(bytes(data))
    with pytest.raises(InputError, match="crafted.npz.*not a readable .npz file.*NotImplementedError"):
        read_npz(path, {"q": (np.dtype("<f8"), (3,))})
