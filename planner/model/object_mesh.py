"""Loading a user's mesh (an object or an obstacle): checked, repaired, scaled, turned upright, and rejected with an
InputError the user can act on (the defect named: holes, non-manifold edges, inconsistent winding, size and unit)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from planner.core.errors import InputError

FORMATS = {".obj": "obj", ".stl": "stl", ".ply": "ply", ".off": "off", ".glb": "glb"}
MAX_FACES = 200_000
# Which axis of a mesh file points up; the rotation turning that axis to +z (world up). glTF meshes are y-up.
UP_AXES = {
    "z": np.eye(3),
    "y": np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]),  # +90 deg about x: y -> z
    "x": np.array([[0.0, 0, -1], [0, 1, 0], [1, 0, 0]]),  # -90 deg about y: x -> z
    "-z": np.diag([1.0, -1.0, -1.0]),  # 180 deg about x
    "-y": np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]]),  # -90 deg about x: -y -> z
    "-x": np.array([[0.0, 0, 1], [0, 1, 0], [-1, 0, 0]]),  # +90 deg about y: -x -> z
}
# Length units a mesh is often exported in, by their size in metres: the likely unit of a mesh of the wrong size.
UNITS = {"millimetres": 0.001, "centimetres": 0.01, "inches": 0.0254, "decimetres": 0.1}


@dataclass(frozen=True)
class SizeLimits:
    """The accepted largest extent (m) of a kind of mesh, and a typical size used to guess a wrong unit."""

    what: str  # "object" or "obstacle", for messages
    low: float
    high: float
    typical: float


OBJECT_LIMITS = SizeLimits("object", 0.01, 2.0, 0.2)  # below 1 cm nothing is regrasped by two hands; above 2 m not carried
OBSTACLE_LIMITS = SizeLimits("obstacle", 0.001, 50.0, 1.0)  # a screw to a room


@dataclass(frozen=True)
class MeshOptions:
    """How a task places a mesh file in metres and z-up: a uniform scale (e.g. 0.001 for millimetres) and its up axis."""

    scale: float = 1.0
    up: str = "z"

    def transform(self) -> np.ndarray:
        """The 4x4 applied to the file's coordinates."""
        T = np.eye(4)
        T[:3, :3] = self.scale * UP_AXES[self.up]
        return T


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
            raise InputError(path, None, "is empty (the file holds no data); expected a closed triangle mesh")
        raise InputError(path, None, f"could not be parsed as a {file_type.upper()} mesh: no triangles were found in it "
                                     "(is it corrupt, truncated, only points/lines, or another format?); "
                                     "expected a closed triangle mesh")
    return loaded


def _repair(mesh: trimesh.Trimesh) -> None:
    """Merge vertices by position alone (seams of UVs and normals split them), drop degenerate and duplicate faces,
    fill holes, fix winding and normals."""
    mesh.merge_vertices(merge_tex=True, merge_norm=True)
    mesh.update_faces(mesh.nondegenerate_faces())
    mesh.update_faces(mesh.unique_faces())
    mesh.remove_unreferenced_vertices()
    trimesh.repair.fix_normals(mesh)
    if not mesh.is_watertight:
        trimesh.repair.fill_holes(mesh)
        trimesh.repair.fix_normals(mesh)


def edge_defects(mesh: trimesh.Trimesh) -> tuple[int, int]:
    """(open edges: used by one triangle, non-manifold edges: used by more than two) of a mesh with merged vertices."""
    _, counts = np.unique(mesh.edges_sorted, axis=0, return_counts=True)
    return int(np.sum(counts == 1)), int(np.sum(counts > 2))


def defect(mesh: trimesh.Trimesh) -> str:
    """What keeps a repaired mesh from being a closed volume, in words; empty when it is one."""
    open_edges, non_manifold = edge_defects(mesh)
    problems = []
    if non_manifold:
        problems.append(f"{non_manifold} non-manifold edges (edges shared by more than two triangles)")
    if open_edges:
        problems.append(f"holes that could not be filled, so it is not watertight ({open_edges} open edges, "
                        "each used by one triangle only)")
    if not problems and not mesh.is_winding_consistent:
        problems.append("inconsistent winding (neighbouring triangles face opposite ways)")
    if not problems and not mesh.is_watertight:
        problems.append("open edges (it is not watertight)")
    if problems:
        return "it has " + " and ".join(problems)
    volume = float(mesh.volume)
    return "" if volume > 0 else f"it encloses no volume (volume {volume:.3g} m^3)"


def likely_unit(size: float, typical: float) -> str:
    """A hint naming the unit a mesh of this largest extent (m) was probably exported in, if it should be about
    `typical`, with the task's `scale` to set."""
    if size > typical:
        unit, metres = min(UNITS.items(), key=lambda u: abs(np.log(size * u[1] / typical)))
        return f"is it in {unit}? then set scale = {metres:g} for this mesh in the task file, or export it in metres"
    factor = 10.0 ** round(np.log10(typical / size))
    return (f"is it in the wrong unit or scaled down? set scale (e.g. scale = {factor:g}) for this mesh in the task file, "
            "or export it in metres")


def _checked_path(path: Path) -> str:
    """The trimesh file type of a mesh path, or an InputError saying what is wrong with the path."""
    if path.is_dir():
        raise InputError(path, None, "is a directory; expected a mesh file (.obj, .stl, .ply, .off or .glb)")
    if not path.is_file():
        raise InputError(path, None, "no such file; expected a mesh file (.obj, .stl, .ply, .off or .glb)")
    file_type = mesh_format(path)
    if path.stat().st_size == 0:
        raise InputError(path, None, "is empty (0 bytes); expected a closed triangle mesh")
    return file_type


def mesh_format(path: Path) -> str:
    """The trimesh file type of a mesh file's name (by its extension), or an InputError listing the formats read."""
    file_type = FORMATS.get(path.suffix.lower())
    if file_type is None:
        raise InputError(path, None, f"unsupported mesh format '{path.suffix or '(no extension)'}'; "
                                     "expected one of .obj, .stl, .ply, .off, .glb")
    return file_type


def check_face_count(count: int, source: str | Path, field: str | None = None) -> None:
    """Refuse a mesh of more than MAX_FACES triangles (checked before it is repaired, or decompressed from a session)."""
    if count > MAX_FACES:
        raise InputError(source, field, f"has {count:,} triangles, more than the {MAX_FACES:,} allowed; "
                                        "simplify (decimate) the mesh first")


def load_mesh(path: str | Path, limits: SizeLimits = OBJECT_LIMITS, options: MeshOptions = MeshOptions()) -> trimesh.Trimesh:
    """Load an OBJ/STL/PLY/OFF/GLB file as one repaired, closed triangle mesh in metres and z-up, within `limits`."""
    path = Path(path)
    return checked_mesh(_read(path, _checked_path(path)), path, limits, options)


def checked_mesh(mesh: trimesh.Trimesh, source: str | Path, limits: SizeLimits, options: MeshOptions | None = MeshOptions()
                 ) -> trimesh.Trimesh:
    """The checks every mesh passes, read from a file or embedded in a session: its triangle count, finite vertices, a
    closed volume and a size within `limits`. A file's mesh is repaired first and placed by `options`; an embedded one
    (`options` None) was saved repaired and placed, and is checked as it is: it is what the session's steps planned on."""
    check_face_count(len(mesh.faces), source)
    if not np.all(np.isfinite(mesh.vertices)):
        raise InputError(source, None, "has vertices with NaN or infinite coordinates; expected finite coordinates")
    try:
        with np.errstate(all="ignore"):  # a flat or open mesh divides by a zero volume in trimesh
            if options is not None:
                _repair(mesh)
            problem = defect(mesh) if len(mesh.faces) else ""
    except Exception as exc:  # a library failure inside the repair: name it, never a traceback
        raise InputError(source, None, f"could not be repaired into a closed mesh ({type(exc).__name__}: {exc})") from exc
    if len(mesh.faces) == 0:
        raise InputError(source, None, "is empty: all its triangles are degenerate; expected a closed triangle mesh")
    if options is not None:
        mesh.apply_transform(options.transform())
    size = float(mesh.extents.max())
    if size < limits.low or size > limits.high:
        shown = f" (after scale = {options.scale:g})" if options is not None and options.scale != 1.0 else ""
        raise InputError(source, None, f"has an absurd size for an {limits.what}: its largest extent is {size:.6g} m{shown}, "
                                       f"expected between {limits.low:g} m and {limits.high:g} m ({likely_unit(size, limits.typical)})")
    if problem:
        raise InputError(source, None, f"is not a closed volume after repair: {problem}; "
                                       "expected a closed, watertight surface around a solid")
    return mesh


def load_object_mesh(path: str | Path, options: MeshOptions = MeshOptions()) -> trimesh.Trimesh:
    """Load an object mesh (metres unless `options` scale it) as one repaired, closed, hand-sized triangle mesh."""
    return load_mesh(path, OBJECT_LIMITS, options)
