"""Generated objects: boxes, cylinders, tori, a mug and capsule animals, made from a few named dimensions (m).

Suite files name a shape and its parameters (`shape = "box"`, `size = [0.22, 0.06, 0.07]`); `tests/generated_objects.py`
plans the same shapes. Every mesh is returned standing on z = 0, centred in x and y: where a task places an object.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np
import trimesh

from planner.core.errors import RegraspError

SIZE_RANGE = (0.10, 0.25)  # m: the largest extent of a generated object (what the default robot's hands can pass between them)


def on_desk(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """The mesh with its bounding box centred in x, y and its bottom at z = 0 (where a task places it)."""
    lo, hi = mesh.bounds
    mesh.apply_translation([-(lo[0] + hi[0]) / 2, -(lo[1] + hi[1]) / 2, -lo[2]])
    return mesh


def capsule_between(a: tuple[float, float, float], b: tuple[float, float, float], radius: float) -> trimesh.Trimesh:
    """A capsule whose axis runs from a to b."""
    pa, pb = np.asarray(a, float), np.asarray(b, float)
    mesh = trimesh.creation.capsule(height=float(np.linalg.norm(pb - pa)), radius=radius, count=[16, 16])
    T = trimesh.geometry.align_vectors([0.0, 0.0, 1.0], pb - pa)
    T[:3, 3] = (pa + pb) / 2
    return mesh.apply_transform(T)


def box(size: tuple[float, float, float]) -> trimesh.Trimesh:
    """A box of these extents (x, y, z)."""
    return trimesh.creation.box(list(size))


def cylinder(radius: float, height: float) -> trimesh.Trimesh:
    """An upright cylinder."""
    return trimesh.creation.cylinder(radius=radius, height=height, sections=48)


def torus(major_radius: float, minor_radius: float) -> trimesh.Trimesh:
    """A torus lying flat: ring radius and tube radius."""
    return trimesh.creation.torus(major_radius=major_radius, minor_radius=minor_radius, major_sections=48, minor_sections=20)


def mug(radius: float = 0.042, height: float = 0.11) -> trimesh.Trimesh:
    """A mug: a revolved cup (closed bottom, open cavity, 6 mm walls) with a ring handle."""
    wall = 0.006
    profile = [[0.0, 0.0], [radius, 0.0], [radius, height], [radius - wall, height], [radius - wall, 0.008], [0.0, 0.008]]
    cup = trimesh.creation.revolve(profile, sections=48)
    handle = trimesh.creation.torus(major_radius=0.03, minor_radius=0.007, major_sections=32, minor_sections=12)
    handle.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
    handle.apply_translation([radius + 0.02, 0.0, height - 0.052])
    return trimesh.boolean.union([cup, handle], engine="manifold")


def animal(body: float, neck: tuple[float, float], leg: float, radius: float) -> trimesh.Trimesh:
    """A four-legged capsule animal: body length, neck (forward, up), leg length, body radius."""
    hip, z = body / 2, leg + radius
    parts = [capsule_between((-hip, 0, z), (hip, 0, z), radius),
             capsule_between((hip, 0, z), (hip + neck[0], 0, z + neck[1]), radius * 0.55),
             capsule_between((hip + neck[0], 0, z + neck[1]), (hip + neck[0] + 0.035, 0, z + neck[1] - 0.01), radius * 0.5)]
    for x in (hip * 0.8, -hip * 0.8):
        for y in (radius * 0.6, -radius * 0.6):
            parts.append(capsule_between((x, y, z), (x, y, 0.008), radius * 0.35))
    return trimesh.boolean.union(parts, engine="manifold")


@dataclass(frozen=True)
class Shape:
    """A generator and its parameters: name -> how many numbers (1: a number, n: a list of n), and the optional ones' defaults."""

    make: Callable[..., trimesh.Trimesh]
    params: Mapping[str, int]
    defaults: Mapping[str, float] = field(default_factory=dict)


SHAPES: dict[str, Shape] = {
    "box": Shape(box, {"size": 3}),
    "cylinder": Shape(cylinder, {"radius": 1, "height": 1}),
    "torus": Shape(torus, {"major_radius": 1, "minor_radius": 1}),
    "mug": Shape(mug, {"radius": 1, "height": 1}, {"radius": 0.042, "height": 0.11}),
    "animal": Shape(animal, {"body": 1, "neck": 2, "leg": 1, "radius": 1}),
}


def generate(shape: str, params: Mapping[str, float | tuple[float, ...]]) -> trimesh.Trimesh:
    """The named shape with these parameters, standing on z = 0; a RegraspError unless it is a closed volume of SIZE_RANGE."""
    mesh = on_desk(SHAPES[shape].make(**params))
    lo, hi = SIZE_RANGE
    if not (mesh.is_watertight and mesh.volume > 0):
        raise RegraspError(f"the {shape} is not a closed volume (parts too thin or overlapping badly)")
    if not lo <= mesh.extents.max() <= hi:
        raise RegraspError(f"the {shape} is {mesh.extents.max():.3g} m long at its largest; expected {lo:g} to {hi:g} m "
                           f"(extents {np.round(mesh.extents, 3).tolist()})")
    return mesh


def obj_text(mesh: trimesh.Trimesh) -> str:
    """The mesh as OBJ text (vertices and faces, 6 digits): what a generated object's file holds."""
    return trimesh.exchange.obj.export_obj(mesh, include_normals=False, include_texture=False, digits=6)
