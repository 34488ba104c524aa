"""The `double_grasps` step drawn (paper IV-B, V-C): a selector over the ranked double grasps; the chosen pair's object at
its exchange pose with both hands on it (the picking hand at its pick grasp, the placing hand at its place grasp, each in
its arm's colour), and buttons putting the robot at the pair's grasp, exchange or place configuration."""
from __future__ import annotations

import numpy as np
import viser

from planner.core.plain_text import plain
from planner.core.session import Session
from planner.grasping.grasp_list import GraspList, hand_spec_of
from planner.handover.double_grasps import DoubleGrasps
from planner.model.hand_model import load_hand_model
from planner.model.task import Scene

from ..meshes import matrix_wxyz
from ..scene_layer import OBJECT_COLOR
from .arms import ARM_COLORS
from .base import Host, Pose, StepLayer
from .hands import HandMeshes
from .stages import stages_markdown

PHASES = {"grasp": "q_grasp", "exchange": "q_exch", "place": "q_place"}  # button -> the result's configurations
HAND_OPACITY = 0.8


def pair_labels(result: DoubleGrasps) -> tuple[str, ...]:
    """Dropdown labels, best pair first: '<pair>: pick <rank> + place <rank>, score <s>' (1-based, as the grasp layers)."""
    return tuple(f"{k + 1}: pick {result.pick_rank[k] + 1} + place {result.place_rank[k] + 1}, score {result.score[k]:.3f}"
                 for k in range(len(result)))


def pair_of(label: str) -> int:
    return int(label.split(":", 1)[0]) - 1


class DoubleGraspsLayer(StepLayer):
    """The ranked double grasps: the chosen pair on the object at the exchange, and the robot at one of its configurations."""

    def __init__(self, server: viser.ViserServer, scene: Scene, root: str, workbench: Host | None = None,
                 session: Session | None = None):
        super().__init__(server, scene, root, workbench, session)
        self.result: DoubleGrasps | None = None
        self.index = 0  # the pair shown
        self.phase: str | None = None  # the configuration the robot was last put at (kept when another pair is chosen)
        self.pair: viser.GuiDropdownHandle | None = None
        self.robot_at: viser.GuiButtonGroupHandle | None = None
        self.details: viser.GuiMarkdownHandle | None = None
        self._grasps: tuple[GraspList, GraspList] | None = None
        self._object: viser.FrameHandle | None = None
        self._hands: tuple[HandMeshes, HandMeshes] | None = None

    def update(self, result: DoubleGrasps) -> None:
        self.remove_folder()
        self.result, self.index, self.phase, self.poses = result, 0, None, {}
        self.pair = self.robot_at = None
        if len(result):
            self._draw_object(result)
            self.poses = {self.label(0, phase): self.pose(0, phase) for phase in PHASES}
        self._build_gui(result)
        if len(result):
            self.select(0)

    def _draw_object(self, result: DoubleGrasps) -> None:
        """The object (posed per pair by `select`) with the picking and placing hands on it."""
        spec = self.scene.robot.spec
        self._grasps = (self.earlier("pick_grasps"), self.earlier("place_grasps"))
        node = f"{self.name}/object"
        self._object = self.server.scene.add_frame(node, show_axes=False)
        mesh = self.scene.object_mesh
        self.server.scene.add_mesh_simple(f"{node}/mesh", mesh.vertices, mesh.faces, color=OBJECT_COLOR,
                                          cast_shadow=False, receive_shadow=False)
        self._hands = tuple(
            HandMeshes(self.server, f"{node}/{role}_hand", load_hand_model(hand_spec_of(spec, arm)),
                       color=ARM_COLORS[spec.arm_names.index(arm) % len(ARM_COLORS)], opacity=HAND_OPACITY)
            for role, arm in (("pick", result.picking_arm), ("place", result.placing_arm)))

    def _build_gui(self, result: DoubleGrasps) -> None:
        gui = self.server.gui
        with gui.add_folder("Double grasps") as self.folder:
            if len(result):
                labels = pair_labels(result)
                self.pair = gui.add_dropdown("Pair", labels, initial_value=labels[0], hint="Double grasps, best first")
                self.robot_at = gui.add_button_group("Show robot at", tuple(PHASES))
            self.details = gui.add_markdown(self.summary(result))
        if self.pair is not None and self.robot_at is not None:
            self.pair.on_update(lambda e: self.select(pair_of(e.target.value)))
            self.robot_at.on_click(lambda e: self.show_phase(e.target.value))

    @staticmethod
    def summary(result: DoubleGrasps) -> str:
        return (f"{plain(result.pairs)} pairs with configurations, {plain(result.compatible)} compatible, {plain(result.tried)} tried, "
                f"{len(result)} with an exchange configuration.\n\n" + stages_markdown(result.stages, result.failure))

    def select(self, index: int) -> None:
        """Show pair `index` (0 = best) on the object at its exchange pose; the robot follows if it was put at a phase."""
        r, grasps, hands = self.result, self._grasps, self._hands
        if r is None or grasps is None or hands is None or not 0 <= index < len(r):
            return
        self.index = index
        with self.server.atomic():
            assert self._object is not None
            self._object.wxyz, self._object.position = matrix_wxyz(r.object_exchange[index])
            for hand, g, rank in zip(hands, grasps, (r.pick_rank[index], r.place_rank[index])):
                hand.pose(g.hand_pose[rank], g.finger_q[rank])
        if self.details is not None:
            self.details.content = (f"**Pair {index + 1}** of {len(r)}: pick grasp {r.pick_rank[index] + 1} ({plain(r.picking_arm)} hand), "
                                    f"place grasp {r.place_rank[index] + 1} ({plain(r.placing_arm)} hand); quality {r.quality[index]:.3f}, "
                                    f"configuration {r.config[index]:.3f}, score {r.score[index]:.3f}\n\n{self.summary(r)}")
        if self.pair is not None and pair_of(self.pair.value) != index:
            self.pair.value = pair_labels(r)[index]
        if self.phase is not None:
            self.show_phase(self.phase)

    @staticmethod
    def label(index: int, phase: str) -> str:
        """The "Robot at" label of pair `index` at `phase`."""
        return f"double grasps: pair {index + 1} at {phase} ({PHASES[phase]})"

    def pose(self, index: int, phase: str) -> Pose:
        """Pair `index` at `phase`: the robot's configuration, the object on the desk, between both hands or at its goal."""
        r = self.result
        assert r is not None
        where = {"grasp": self.scene.object_initial, "exchange": r.object_exchange[index], "place": self.scene.object_final}
        return Pose(getattr(r, PHASES[phase])[index], np.asarray(where[phase], float))

    def show_phase(self, name: str) -> None:
        """Put the workbench's robot at the shown pair's grasp, exchange or place configuration (see PHASES), object included."""
        self.phase = name
        if self.workbench is None or self.result is None or not len(self.result):
            return
        pose = self.pose(self.index, name)
        self.workbench.pose_robot(pose.q, pose.object_pose, self.label(self.index, name))
