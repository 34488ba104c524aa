"""The robot's visual meshes, one scene node per geometry, posed by forward kinematics."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import viser

from planner.collision.shapes import to_trimesh
from planner.model.robot import Robot

from .meshes import poses_wxyz
from .rooted import Rooted
from .scene_layer import DIM_OPACITY


class RobotLayer(Rooted):
    """Owns the robot's mesh handles under `root`; `update(q)` poses them."""

    def __init__(self, server: viser.ViserServer, robot: Robot, q: np.ndarray, root: str = "/robot"):
        self.server = server
        self.model = robot.model
        self.geometry = robot.visual_model
        self.data = self.model.createData()
        self.geometry_data = pin.GeometryData(self.geometry)
        super().__init__(server, root)
        self.handles: list[viser.MeshHandle] = []
        for obj in self.geometry.geometryObjects:
            mesh = to_trimesh(obj.geometry, obj.meshScale)
            rgb = tuple(int(255 * c) for c in np.asarray(obj.meshColor)[:3])
            self.handles.append(server.scene.add_mesh_simple(
                f"{root}/{obj.name}", mesh.vertices, mesh.faces, color=rgb, cast_shadow=False, receive_shadow=False))
        self.update(q)

    def dim(self, dimmed: bool) -> None:
        """Draw the robot translucent (so that what is in focus stands out), or opaque again."""
        with self.server.atomic():
            for handle in self.handles:
                handle.opacity = DIM_OPACITY if dimmed else None

    def update(self, q: np.ndarray) -> None:
        """Pose every link at q in one atomic batch (viser sends only the poses that changed)."""
        pin.updateGeometryPlacements(self.model, self.data, self.geometry, self.geometry_data, np.asarray(q, float))
        wxyz, xyz = poses_wxyz(list(self.geometry_data.oMg))
        with self.server.atomic():
            for handle, w, p in zip(self.handles, wxyz, xyz):
                handle.wxyz, handle.position = w, p
