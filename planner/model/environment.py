"""Static obstacles of a scene: primitives and meshes with their world poses."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import trimesh

from planner.collision.shapes import Geometry, primitive

SHAPES = {"box": 3, "cylinder": 2, "sphere": 1, "capsule": 2, "mesh": 0}


@dataclass(frozen=True, eq=False)
class Obstacle:
    """One static obstacle. size: box (x, y, z); cylinder/capsule (radius, length); sphere (radius,)."""

    name: str
    shape: str
    size: tuple[float, ...]
    pose: np.ndarray
    color: tuple[int, int, int] = (170, 160, 150)
    mesh: trimesh.Trimesh | None = field(default=None, repr=False)

    def to_trimesh(self) -> trimesh.Trimesh:
        """The obstacle as a mesh in world coordinates (for display and mesh-level checks)."""
        if self.shape == "box":
            m = trimesh.creation.box(extents=self.size)
        elif self.shape == "cylinder":
            m = trimesh.creation.cylinder(radius=self.size[0], height=self.size[1], sections=32)
        elif self.shape == "capsule":
            m = trimesh.creation.capsule(radius=self.size[0], height=self.size[1], count=[16, 16])
        elif self.shape == "sphere":
            m = trimesh.creation.icosphere(subdivisions=3, radius=self.size[0])
        else:
            m = self.mesh.copy()
        m.apply_transform(self.pose)
        return m

    def coal_shape(self) -> Geometry:
        """The obstacle's exact collision shape in its own frame."""
        return primitive(self.shape, self.size, self.mesh)


Environment = tuple[Obstacle, ...]
