"""The simplified collision geometry (robot hulls, obstacles grown by their padding), colliding parts in red."""
from __future__ import annotations

from collections.abc import Iterable

import numpy as np
import pinocchio as pin
import viser

from planner.collision.checker import CollisionModel
from planner.collision.shapes import to_trimesh

from .meshes import poses_wxyz

ROBOT_STYLE = ((80, 150, 255), 0.35)
ENV_STYLE = ((255, 170, 60), 0.3)
HIT_STYLE = ((235, 30, 30), 0.85)


class CollisionLayer:
    """Owns one handle per collision geometry; shown all at once, or only the colliding ones."""

    def __init__(self, server: viser.ViserServer, cm: CollisionModel, root: str = "/collision"):
        self.server = server
        self.root = server.scene.add_frame(root, show_axes=False)
        self.model = cm.robot.model
        self.geometry = cm.geometry
        self.n_robot = cm.n_robot_geoms
        self.data = self.model.createData()
        self.geometry_data = pin.GeometryData(self.geometry)
        self.shown = False
        self.colliding: frozenset[str] = frozenset()
        self.handles: dict[str, viser.MeshHandle] = {}
        for i, obj in enumerate(self.geometry.geometryObjects):
            mesh = to_trimesh(obj.geometry, obj.meshScale, grow=0.0 if i < self.n_robot else cm.params.env_padding)
            color, opacity = ROBOT_STYLE if i < self.n_robot else ENV_STYLE
            self.handles[obj.name] = server.scene.add_mesh_simple(
                f"{root}/{obj.name}", mesh.vertices, mesh.faces, color=color, opacity=opacity, flat_shading=True,
                cast_shadow=False, receive_shadow=False, visible=False)

    def update(self, q: np.ndarray, colliding: Iterable[str]) -> None:
        """Pose the geometries at q and paint the named colliding geometries red."""
        pin.updateGeometryPlacements(self.model, self.data, self.geometry, self.geometry_data, np.asarray(q, float))
        wxyz, xyz = poses_wxyz(list(self.geometry_data.oMg))
        hit = frozenset(colliding)
        with self.server.atomic():
            for i, (name, handle) in enumerate(self.handles.items()):
                was, now = name in self.colliding, name in hit
                if was != now:
                    handle.color, handle.opacity = HIT_STYLE if now else ROBOT_STYLE if i < self.n_robot else ENV_STYLE
                handle.visible = self.shown or now
                if handle.visible:
                    handle.wxyz, handle.position = wxyz[i], xyz[i]
        self.colliding = hit

    def show(self, shown: bool, q: np.ndarray) -> None:
        """Show every collision geometry, or only the colliding ones."""
        self.shown = shown
        self.update(q, self.colliding)

    def remove(self) -> None:
        """Take the collision geometry out of the scene."""
        self.root.remove()
