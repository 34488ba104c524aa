"""Loading a user's object mesh (metres): checked, repaired, and rejected with an InputError the user can act on."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from .errors import InputError

FORMATS = {".obj": "obj", ".stl": "stl", ".ply": "ply", ".off": "off", ".glb": "glb"}
MIN_EXTENT = 0.01  # m: smaller than 1 cm is not something two hands regrasp
MAX_EXTENT = 2.0  # m
MAX_FACES = 200_000


@dataclass(frozen=True)
class ObjectInfo:
    """A summary of an object mesh, for reports and the workbench."""

    n_vertices: int
    n_faces: int
    extents: tuple[float, float, float]
    volume: float
    center_mass: tuple[float, float, float]


def object_info(mesh: trimesh.Trimesh) -> ObjectInfo:
    """Counts, bounding-box extents (m), volume (m^3) and centre of mass of a mesh."""
    return ObjectInfo(
        n_vertices=len(mesh.vertices),
        n_faces=len(mesh.faces),
        extents=tuple(float(e) for e in mesh.extents),
        volume=float(mesh.volume),
        center_mass=tuple(float(c) for c in mesh.center_mass),
    )


def _read(path: Path, file_type: str) -> trimesh.Trimesh:
    """Parse the file into one triangle mesh (scenes concatenated); any parser failure becomes an InputError."""
    try:
        # force="mesh" concatenates every geometry of a scene (e.g. a multi-part GLB) into one mesh
        loaded = trimesh.load(str(path), file_type=file_type, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many kinds for malformed files
        reason = str(exc).strip().splitlines()[0][:200] if str(exc).strip() else type(exc).__name__
        raise InputError(path, None, f"could not be parsed as a {file_type.upper()} mesh ({reason}); "
                                     "expected a valid mesh file") from exc
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        if not path.read_bytes().strip():
            raise InputError(path, None, "is empty (the file holds no data); expected a closed triangle mesh of the object")
        raise InputError(path, None, f"could not be parsed as a {file_type.upper()} mesh: no triangles were found in it "
                                     "(is it corrupt, truncated, only points/lines, or another format?); "
                                     "expected a closed triangle mesh of the object")
    return loaded


def _repair(mesh: trimesh.Trimesh) -> None:
    """Merge duplicate vertices, drop degenerate and duplicate faces, fill small holes, fix winding and normals."""
    mesh.merge_vertices()
    mesh.update_faces(mesh.nondegenerate_faces())
    mesh.update_faces(mesh.unique_faces())
    mesh.remove_unreferenced_vertices()
    trimesh.repair.fix_normals(mesh)
    trimesh.repair.fill_holes(mesh)
    trimesh.repair.fix_normals(mesh)


def load_object_mesh(path: str | Path) -> trimesh.Trimesh:
    """Load an OBJ/STL/PLY/OFF/GLB object (metres) as one repaired, closed, hand-sized triangle mesh."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, None, "no such file; expected an object mesh (.obj, .stl, .ply, .off or .glb)")
    file_type = FORMATS.get(path.suffix.lower())
    if file_type is None:
        raise InputError(path, None, f"unsupported mesh format '{path.suffix or '(no extension)'}'; "
                                     "expected one of .obj, .stl, .ply, .off, .glb")
    if path.stat().st_size == 0:
        raise InputError(path, None, "is empty (0 bytes); expected a closed triangle mesh of the object")
    mesh = _read(path, file_type)
    if len(mesh.faces) > MAX_FACES:
        raise InputError(path, None, f"has {len(mesh.faces):,} triangles, more than the {MAX_FACES:,} allowed; "
                                     "simplify (decimate) the mesh first")
    if not np.all(np.isfinite(mesh.vertices)):
        raise InputError(path, None, "has vertices with NaN or infinite coordinates; expected finite coordinates")
    try:
        with np.errstate(all="ignore"):  # a flat or open mesh divides by a zero volume in trimesh
            _repair(mesh)
            watertight, volume = mesh.is_watertight, float(mesh.volume)
    except Exception as exc:
        raise InputError(path, None, f"could not be repaired into a closed mesh ({type(exc).__name__}: {exc})") from exc
    if len(mesh.faces) == 0:
        raise InputError(path, None, "is empty: all its triangles are degenerate; expected a closed triangle mesh")
    size = float(mesh.extents.max())
    if size < MIN_EXTENT or size > MAX_EXTENT:
        hint = ("is it in millimetres or centimetres? export it in metres"
                if size > MAX_EXTENT else "is it in the wrong unit (e.g. kilometres) or scaled down? export it in metres")
        raise InputError(path, None, f"has an absurd size: its largest extent is {size:.6g} m, expected between "
                                     f"{MIN_EXTENT} m and {MAX_EXTENT} m ({hint})")
    if not watertight or volume <= 0:
        problem = "is not watertight (it has holes or open edges)" if not watertight else \
            f"encloses no volume (volume {volume:.3g} m^3)"
        raise InputError(path, None, f"is not a closed volume after repair: it {problem}; "
                                     "expected a closed, watertight surface around a solid object")
    return mesh
