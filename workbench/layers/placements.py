"""The `placements` step drawn: a dot at the object's centre of mass at each stable placement, coloured by which arms
reach it (both: green; one: that arm's colour; none: grey), the stage table saying why others were dropped, and the
object shown at the first placement (the one a table handover tries first)."""
from __future__ import annotations

import numpy as np

from planner.core.plain_text import plain
from planner.regrasp.placements import Placements

from .arms import ARM_COLORS
from .base import Pose, StepLayer
from .stages import stages_markdown

BOTH_COLOR = (30, 180, 60)
NONE_COLOR = (150, 150, 150)
DOT_SIZE = 0.015  # m


def reach_colors(reached: np.ndarray) -> np.ndarray:
    """(n, 3) uint8 per placement from its (n, arms) reach flags: green for all arms, an arm's colour for it alone, grey
    for none."""
    colors = np.tile(np.array(NONE_COLOR, np.uint8), (len(reached), 1))
    for k in range(reached.shape[1] if reached.ndim == 2 else 0):
        colors[reached[:, k]] = ARM_COLORS[k % len(ARM_COLORS)]
    if len(reached) and reached.ndim == 2:
        colors[reached.all(axis=1)] = BOTH_COLOR
    return colors


class PlacementsLayer(StepLayer):
    """The stable placements by reach, and the object at the first of them."""

    def update(self, result: Placements) -> None:
        self.remove_folder()
        com = np.asarray(self.scene.object_mesh.center_mass, float)
        centres = result.pose[:, :3, :3] @ com + result.pose[:, :3, 3]
        if len(centres):
            self.server.scene.add_point_cloud(f"{self.name}/placements", centres.astype(np.float32), reach_colors(result.reached),
                                              point_size=DOT_SIZE, point_shape="circle", precision="float32")
        self.poses = {"placements: the object at the first placement": Pose(self.scene.q_initial, result.pose[0])} if len(result) else {}
        arms = ", ".join(f"{plain(a)}: {int(result.reached[:, k].sum())}" for k, a in enumerate(result.arms))
        supports = plain(", ".join(sorted(set(result.support))) or "no support")
        self.folder = self.server.gui.add_folder("Placements", expand_by_default=False)
        with self.folder:
            self.server.gui.add_markdown(f"{len(result)} stable placements on {supports}; reached by {arms}. Dots at the centre of "
                                         "mass: green = both arms reach it, an arm's colour = that arm alone, grey = neither.\n\n"
                                         + stages_markdown(result.stages, ""))
