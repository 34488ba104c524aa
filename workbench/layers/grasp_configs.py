"""The `grasp_configs` step drawn (paper IV-B filter, V-C): every grasp of the pick list at the initial object pose and
of the place list at the final one, as a palm dot with a stroke towards the grasp centre, coloured by how far it got:
it has a robot configuration (green), its hand clears the environment but no configuration was found (yellow), or
the environment filter removed it (red). The best-scored configuration of each hand is offered as a robot pose."""
from __future__ import annotations

import numpy as np

from planner.core.plain_text import plain
from planner.grasping.grasp_list import GraspList
from planner.handover.grasp_configs import GraspConfigs
from planner.handover.reach import fingertip_centre

from .base import Pose, StepLayer
from .stages import stages_markdown

KEPT_COLOR = (30, 180, 60)
CLEAR_COLOR = (240, 200, 30)
REMOVED_COLOR = (220, 40, 40)
PALM_SIZE = 0.012  # m: the dot at a palm
APPROACH_LENGTH = 0.035  # m: the stroke from the palm towards the grasp centre
ROLES = (("pick", "initial"), ("place", "final"))


def grasp_colors(env_free: np.ndarray, ranks: np.ndarray) -> np.ndarray:
    """(n, 3) uint8 per grasp of a list: green with a configuration, yellow clear of the environment only, else red."""
    colors = np.tile(np.array(REMOVED_COLOR, np.uint8), (len(env_free), 1))
    colors[env_free] = CLEAR_COLOR
    colors[ranks] = KEPT_COLOR
    return colors


def palm_marks(grasps: GraspList, object_pose: np.ndarray, centre: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World palm positions (n, 3) and strokes (n, 2, 3) from each palm towards its grasp centre, object at object_pose."""
    palms = object_pose @ grasps.hand_pose  # (n, 4, 4) palm frames in the world
    direction = APPROACH_LENGTH * centre / np.linalg.norm(centre)
    origins = palms[:, :3, 3]
    return origins, np.stack([origins, origins + palms[:, :3, :3] @ direction], axis=1)


class GraspConfigsLayer(StepLayer):
    """The filtered pick and place lists at their placements, and the best grasp / place configurations."""

    def update(self, result: GraspConfigs) -> None:
        self.remove_folder()
        self.poses = {}
        lines = []
        for role, placement in ROLES:
            grasps: GraspList = self.earlier(f"{role}_grasps")
            configs = result.hand(role)
            env_free = result.pick_env_free if role == "pick" else result.place_env_free
            T = self.scene.object_initial if placement == "initial" else self.scene.object_final
            palms, strokes = palm_marks(grasps, np.asarray(T, float), fingertip_centre(self.scene.robot, grasps.hand))
            colors = grasp_colors(env_free, configs.rank)
            if len(palms):
                self.server.scene.add_point_cloud(f"{self.name}/{role}/palms", palms.astype(np.float32), colors,
                                                  point_size=PALM_SIZE, point_shape="circle", precision="float32")
                self.server.scene.add_line_segments(f"{self.name}/{role}/approach", strokes.astype(np.float32),
                                                    np.repeat(colors[:, None], 2, axis=1), thickness=0.003)
            if len(configs.rank):
                best = int(np.argmax(configs.score))
                self.poses[f"grasp configs: best {role} (rank {configs.rank[best] + 1})"] = Pose(configs.q[best], np.asarray(T, float))
            kept, clear = len(configs.rank), int(env_free.sum())
            lines.append(f"- **{role}** ({plain(configs.arm)} hand, {placement} pose): {kept} with a configuration, "
                         f"{clear - kept} clear only, {len(env_free) - clear} removed")
        self.folder = self.server.gui.add_folder("Grasp configurations")
        with self.folder:
            self.server.gui.add_markdown("Palms: green = configuration, yellow = clear of the environment only, red = removed\n\n"
                                         + "\n".join(lines) + "\n\n" + stages_markdown(result.stages, result.failure))
