"""A hand drawn by its collision shapes (the URDF's boxes and spheres, fingertips highlighted), shared by the grasp layers."""
from __future__ import annotations

import numpy as np
import viser

from planner.collision.shapes import to_trimesh
from planner.model.hand_model import HandModel

from ..meshes import matrix_wxyz

HAND_STYLE = ((200, 200, 210), 0.6)  # colour, opacity
TIP_COLOR = (250, 200, 40)


class HandMeshes:
    """One hand's shapes under the frame `node`; `pose(T, finger_q)` puts the hand frame at T and the fingers at finger_q."""

    def __init__(self, server: viser.ViserServer, node: str, hand: HandModel, color: tuple[int, int, int] = HAND_STYLE[0],
                 opacity: float = HAND_STYLE[1], visible: bool = True):
        self.server = server
        self.hand = hand
        self.node = node
        self.frame = server.scene.add_frame(node, show_axes=False, visible=visible)
        self.shapes: list[viser.MeshHandle] = []
        for i, (shape, _) in enumerate(hand.shape_poses(hand.open_q)):
            mesh = to_trimesh(shape.geometry)
            self.shapes.append(server.scene.add_mesh_simple(
                f"{node}/shape_{i}", mesh.vertices, mesh.faces, color=TIP_COLOR if shape.is_tip else color, opacity=opacity,
                flat_shading=True, cast_shadow=False, receive_shadow=False))

    def pose(self, T: np.ndarray, finger_q: np.ndarray) -> None:
        """Hand frame at T (in the parent node's frame), fingers at finger_q; shows the hand."""
        with self.server.atomic():
            self.frame.wxyz, self.frame.position = matrix_wxyz(np.asarray(T, float))
            self.frame.visible = True
            for handle, (_, pose) in zip(self.shapes, self.hand.shape_poses(finger_q)):
                handle.wxyz, handle.position = matrix_wxyz(pose)
