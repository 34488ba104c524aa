"""The task's static world: obstacles, the object at its initial pose and a ghost at its final pose."""
from __future__ import annotations

import numpy as np
import viser

from planner.model.task import Scene

from .meshes import matrix_wxyz

OBJECT_COLOR = (214, 170, 70)
GHOST_OPACITY = 0.35
DIM_OPACITY = 0.2  # of the robot and the obstacles while something else is in focus


class SceneLayer:
    """Owns the obstacle, object and ghost handles under `root`."""

    def __init__(self, server: viser.ViserServer, scene: Scene, root: str = "/scene"):
        self.root = server.scene.add_frame(root, show_axes=False)
        self.obstacles = [
            server.scene.add_mesh_simple(f"{root}/obstacles/{ob.name}", m.vertices, m.faces, color=ob.color,
                                         flat_shading=ob.shape == "box", cast_shadow=False, receive_shadow=False)
            for ob in scene.environment for m in [ob.to_trimesh()]
        ]
        self.mesh = mesh = scene.object_mesh
        wxyz, xyz = matrix_wxyz(scene.object_initial)
        self.object = server.scene.add_mesh_simple(f"{root}/object", mesh.vertices, mesh.faces, color=OBJECT_COLOR,
                                                   wxyz=wxyz, position=xyz, cast_shadow=False, receive_shadow=False)
        wxyz, xyz = matrix_wxyz(scene.object_final)
        self.ghost = server.scene.add_mesh_simple(f"{root}/ghost", mesh.vertices, mesh.faces, color=OBJECT_COLOR,
                                                  opacity=GHOST_OPACITY, wxyz=wxyz, position=xyz,
                                                  cast_shadow=False, receive_shadow=False)

    def dim(self, dimmed: bool) -> None:
        """Draw the obstacles translucent (so that what is in focus stands out), or opaque again."""
        for handle in self.obstacles:
            handle.opacity = DIM_OPACITY if dimmed else None

    def centre(self, T: np.ndarray) -> np.ndarray:
        """The object's centre of mass in the world when the object is at pose T."""
        T = np.asarray(T, float)
        return T[:3, :3] @ np.asarray(self.mesh.center_mass) + T[:3, 3]

    def place_object(self, T: np.ndarray) -> None:
        """Draw the object at pose T (world frame): where the configuration shown has it."""
        self.object.wxyz, self.object.position = matrix_wxyz(np.asarray(T, float))

    def remove(self) -> None:
        """Take the scene's nodes out of the viewer."""
        self.root.remove()
