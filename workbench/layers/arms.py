"""The `arms` step drawn: a halo and a label in the arm's colour at each placement, and the two witness poses."""
from __future__ import annotations

import numpy as np

from planner.handover.arms import ArmAssignment

from .base import Pose, StepLayer

ARM_COLORS = ((40, 110, 240), (230, 90, 30), (30, 170, 80), (170, 60, 200))  # by the arm's index in the robot spec
HALO_RADIUS = 0.17  # m: around the statuette-sized object
HALO_OPACITY = 0.3
LABEL_HEIGHT = 0.35  # m above the object's centre of mass


class ArmsLayer(StepLayer):
    """Which arm picks (at the initial placement) and which places (at the final one)."""

    def update(self, result: ArmAssignment) -> None:
        scene = self.scene
        arms = scene.robot.spec.arm_names
        com = np.asarray(scene.object_mesh.center_mass)
        roles = (("initial", scene.object_initial, result.picking_arm, "picks"),
                 ("final", scene.object_final, result.placing_arm, "places"))
        for placement, T, arm, role in roles:
            color = ARM_COLORS[arms.index(arm) % len(ARM_COLORS)]
            centre = T[:3, :3] @ com + T[:3, 3]
            top = centre + (0.0, 0.0, LABEL_HEIGHT)
            node = f"{self.name}/{placement}"
            self.server.scene.add_icosphere(f"{node}/halo", radius=HALO_RADIUS, color=color, opacity=HALO_OPACITY,
                                            position=centre, cast_shadow=False, receive_shadow=False)
            self.server.scene.add_line_segments(f"{node}/stem", np.array([[centre, top]]), color, thickness=0.008)
            self.server.scene.add_label(f"{node}/label", f"{arm} arm {role}", position=top, anchor="bottom-center")
        self.poses = {f"arms: {result.picking_arm} arm picks (q_pick)": Pose(result.q_pick, scene.object_initial),
                      f"arms: {result.placing_arm} arm places (q_place)": Pose(result.q_place, scene.object_final)}
