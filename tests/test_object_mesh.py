"""Tests of object-mesh loading (planner.model.object_mesh) and of the generated statuette (planner.model.statuette)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from planner.core.errors import InputError
from planner.model.object_mesh import load_object_mesh
from planner.model.statuette import STATUETTE_PATH

FORMATS = ["obj", "stl", "ply", "off", "glb"]


def _torus() -> trimesh.Trimesh:
    """A hand-sized torus: watertight and genus one."""
    return trimesh.creation.torus(major_radius=0.06, minor_radius=0.02, major_sections=48, minor_sections=24)


def _mug() -> trimesh.Trimesh:
    """A mug-like cup (closed bottom, open cavity, thick wall) revolved from its cross-section."""
    profile = [[0.0, 0.0], [0.04, 0.0], [0.04, 0.09], [0.035, 0.09], [0.035, 0.006], [0.0, 0.006]]
    return trimesh.creation.revolve(profile, sections=48)


def _load_error(path: Path) -> str:
    """The message of the InputError that loading path raises; it must name the file."""
    with pytest.raises(InputError) as info:
        load_object_mesh(path)
    message = str(info.value)
    assert str(path) in message and info.value.source == str(path)
    return message


# --- the statuette -------------------------------------------------------------------------------

def test_statuette_file_loads_and_is_a_closed_hand_sized_nonconvex_solid() -> None:
    mesh = load_object_mesh(STATUETTE_PATH)
    assert mesh.is_watertight and mesh.volume > 0
    assert 500 <= len(mesh.vertices) <= 900
    assert 1000 <= len(mesh.faces) <= 1600
    assert 0.2 <= mesh.extents.max() <= 0.3
    assert mesh.volume / mesh.convex_hull.volume < 0.6  # legs, neck, tail: far from convex


def test_statuette_stands_on_its_feet_at_the_origin() -> None:
    mesh = load_object_mesh(STATUETTE_PATH)
    assert mesh.bounds[0, 2] == pytest.approx(0.0, abs=1e-6)
    feet = mesh.vertices[mesh.vertices[:, 2] < 1e-3]
    centre = (feet[:, :2].min(axis=0) + feet[:, :2].max(axis=0)) / 2
    assert np.allclose(centre, 0.0, atol=1e-4)
    # four separate feet: the contact points split into four clusters, one per quadrant
    quadrants = {(bool(x > 0), bool(y > 0)) for x, y in feet[:, :2]}
    assert len(quadrants) == 4
    # the centre of mass is above the footprint, so the figure stands
    lo, hi = feet[:, :2].min(axis=0), feet[:, :2].max(axis=0)
    assert np.all(lo < mesh.center_mass[:2]) and np.all(mesh.center_mass[:2] < hi)


def test_make_statuette_is_deterministic_and_matches_the_committed_file() -> None:
    pytest.importorskip("manifold3d")
    pytest.importorskip("fast_simplification")
    from planner.model.statuette import make_statuette

    a, b = make_statuette(), make_statuette()
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)
    assert a.is_watertight and a.volume > 0
    stored = trimesh.load(STATUETTE_PATH, force="mesh", process=False)
    assert len(stored.vertices) == len(a.vertices) and len(stored.faces) == len(a.faces)


def test_write_statuette_writes_a_loadable_obj(tmp_path: Path) -> None:
    pytest.importorskip("manifold3d")
    pytest.importorskip("fast_simplification")
    from planner.model.statuette import write_statuette

    path = write_statuette(tmp_path / "sub" / "horse.obj")
    assert path.is_file()
    assert len(load_object_mesh(path).faces) == len(load_object_mesh(STATUETTE_PATH).faces)


# --- good inputs in every format -----------------------------------------------------------------

@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("make", [_torus, _mug], ids=["torus", "mug"])
def test_closed_meshes_load_in_every_format(tmp_path: Path, fmt: str, make) -> None:
    original = make()
    assert original.is_watertight
    path = tmp_path / f"object.{fmt}"
    original.export(path)
    mesh = load_object_mesh(path)
    assert isinstance(mesh, trimesh.Trimesh)
    assert mesh.is_watertight and mesh.volume > 0
    assert len(mesh.faces) == len(original.faces)
    assert mesh.volume == pytest.approx(original.volume, rel=1e-4)
    assert np.allclose(mesh.extents, original.extents, atol=1e-6)


def test_glb_with_several_geometries_is_concatenated(tmp_path: Path) -> None:
    box = trimesh.creation.box([0.05, 0.05, 0.05], transform=trimesh.transformations.translation_matrix([0.2, 0, 0]))
    path = tmp_path / "two.glb"
    trimesh.Scene([_torus(), box]).export(path)
    mesh = load_object_mesh(path)
    assert len(mesh.faces) == len(_torus().faces) + len(box.faces)
    assert mesh.volume == pytest.approx(_torus().volume + box.volume, rel=1e-4)


def test_duplicate_vertices_and_faces_and_flipped_winding_are_repaired(tmp_path: Path) -> None:
    box = trimesh.creation.box([0.1, 0.1, 0.1])
    faces = box.faces.copy()
    faces[:3] = faces[:3, ::-1]  # three triangles wound the wrong way
    faces = np.vstack([faces, faces[:1]])  # a duplicate face
    triangles = box.vertices[faces]  # one vertex per corner of every face: all duplicated
    path = tmp_path / "messy.obj"
    lines = [f"v {x} {y} {z}" for x, y, z in triangles.reshape(-1, 3)]
    lines += [f"f {3 * i + 1} {3 * i + 2} {3 * i + 3}" for i in range(len(faces))]
    path.write_text("\n".join(lines) + "\n")
    mesh = load_object_mesh(path)
    assert (len(mesh.vertices), len(mesh.faces)) == (8, 12)
    assert mesh.is_watertight and mesh.volume == pytest.approx(0.001, rel=1e-6)


def test_a_small_hole_is_filled(tmp_path: Path) -> None:
    box = trimesh.creation.box([0.1, 0.1, 0.1])
    box.update_faces(np.arange(1, 12))  # one triangle missing
    path = tmp_path / "holed.stl"
    box.export(path)
    mesh = load_object_mesh(path)
    assert mesh.is_watertight and mesh.volume == pytest.approx(0.001, rel=1e-5)


# --- bad inputs: each names the file and what is wrong --------------------------------------------

def test_missing_file(tmp_path: Path) -> None:
    assert "no such file" in _load_error(tmp_path / "nowhere.obj")


def test_a_directory_is_not_a_file(tmp_path: Path) -> None:
    (tmp_path / "dir.obj").mkdir()
    assert "is a directory; expected a mesh file" in _load_error(tmp_path / "dir.obj")


def test_unsupported_format(tmp_path: Path) -> None:
    path = tmp_path / "points.xyz"
    path.write_text("0 0 0\n1 0 0\n0 1 0\n")
    message = _load_error(path)
    assert "unsupported mesh format '.xyz'" in message and ".obj" in message and ".glb" in message


def test_garbage_stl_cannot_be_parsed(tmp_path: Path) -> None:
    path = tmp_path / "garbage.stl"
    path.write_bytes(bytes(range(256)) * 7 + b"not a mesh at all \x00\xff" * 11)
    assert "could not be parsed as a STL mesh" in _load_error(path)


@pytest.mark.parametrize("fmt", ["ply", "glb", "off"])
def test_garbage_in_other_formats_cannot_be_parsed(tmp_path: Path, fmt: str) -> None:
    path = tmp_path / f"garbage.{fmt}"
    path.write_bytes(b"\x00\x01garbage\xff\xfe" * 50)
    assert f"could not be parsed as a {fmt.upper()} mesh" in _load_error(path)


@pytest.mark.parametrize("content", ["", "\n  \n"], ids=["zero-bytes", "blank"])
def test_empty_obj(tmp_path: Path, content: str) -> None:
    path = tmp_path / "empty.obj"
    path.write_text(content)
    assert "is empty" in _load_error(path)


def test_obj_with_points_but_no_triangles(tmp_path: Path) -> None:
    path = tmp_path / "points.obj"
    path.write_text("v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\n")
    assert "no triangles" in _load_error(path)


def test_single_triangle_is_not_a_closed_volume(tmp_path: Path) -> None:
    path = tmp_path / "triangle.obj"
    path.write_text("v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nf 1 2 3\n")
    message = _load_error(path)
    assert "not a closed volume" in message and "not watertight" in message


def test_open_cylinder_cannot_be_repaired(tmp_path: Path) -> None:
    cylinder = trimesh.creation.cylinder(radius=0.04, height=0.1, sections=32)
    cylinder.update_faces(cylinder.face_normals[:, 2] < 0.9)  # the top cap removed: a 32-edge hole
    path = tmp_path / "open.ply"
    cylinder.export(path)
    message = _load_error(path)
    assert "not a closed volume" in message and "not watertight" in message


@pytest.mark.parametrize(("size", "hint"), [(1000.0, "millimetres"), (0.001, "wrong unit")], ids=["1km", "1mm"])
def test_absurd_size_says_the_size_and_hints_at_units(tmp_path: Path, size: float, hint: str) -> None:
    path = tmp_path / "box.stl"
    trimesh.creation.box([size, size, size]).export(path)
    message = _load_error(path)
    assert "absurd size" in message and f"{size:g} m" in message and hint in message and "metres" in message


def test_too_many_triangles(tmp_path: Path) -> None:
    sphere = trimesh.creation.icosphere(subdivisions=7, radius=0.1)
    assert len(sphere.faces) > 200_000
    path = tmp_path / "dense.stl"
    sphere.export(path)
    message = _load_error(path)
    assert f"{len(sphere.faces):,} triangles" in message and "200,000" in message


def test_non_finite_coordinates(tmp_path: Path) -> None:
    path = tmp_path / "nan.obj"
    path.write_text("v 0 0 0\nv nan 0 0\nv 0 0.1 0\nv 0 0 0.1\nf 1 2 3\nf 1 3 4\nf 1 4 2\nf 2 4 3\n")
    assert "NaN or infinite" in _load_error(path)
