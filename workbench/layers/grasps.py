"""The `pick_grasps` / `place_grasps` steps drawn (paper IV-A, figs. 2-3): a rank selector and the chosen grasp's hand
(its collision shapes), contact points, normals, friction cones and scores, at the object's placement. On request, what
the search worked on: the object's point set coloured by kd-tree leaf and the fingers' workspace sphere hierarchies
(from the planner's `grasping.figures`; a replay draws the saved list alone)."""
from __future__ import annotations

import numpy as np
import trimesh
import viser

from planner.core.plain_text import plain
from planner.core.session import Session
from planner.grasping.figures import finger_spheres, object_points
from planner.grasping.grasp_list import GraspList, hand_spec_of
from planner.model.hand_model import HandModel, load_hand_model
from planner.model.task import Scene

from ..meshes import matrix_wxyz
from .arms import ARM_COLORS
from .base import Host, StepLayer
from .hands import HAND_STYLE, HandMeshes
from .roadmap import faint

POINT_SIZE = 0.003  # m: the object's point set, small and ...
POINT_FADE = 0.55  # ... its leaf colours faded this far toward white, so the contacts stand out of it
CONTACT_COLOR = (220, 0, 40)
CONTACT_RADIUS = 0.006  # m: a sphere at each contact, larger than the point set's dots
NORMAL_COLOR = (20, 20, 20)  # near black: the hands are drawn in the arms' colours
NORMAL_LENGTH = 0.05  # m
NORMAL_THICKNESS = 0.004  # m
CONE_HEIGHT = 0.03  # m
CONE_STYLE = ((255, 140, 0), 0.5)
SPHERE_OPACITY = 0.3
FINGER_COLORS = ((40, 110, 240), (30, 170, 80), (170, 60, 200), (230, 90, 30), (0, 170, 170))


def swatch(color: tuple[int, int, int], mark: str = "&#9679;") -> str:
    """A coloured mark for a legend (HTML)."""
    return f"<span style='color:rgb({color[0]},{color[1]},{color[2]})'>{mark}</span>"


def legend(mu: float, fingers: tuple[str, ...]) -> str:
    """What the grasp layer draws, by colour: contacts, normals, friction cones (their half-angle from μ), the point set
    and each finger's sphere hierarchy (markdown with HTML swatches; the finger names escaped)."""
    spheres = ", ".join(f"{swatch(FINGER_COLORS[k % len(FINGER_COLORS)])} {plain(f)}" for k, f in enumerate(fingers))
    return (f"{swatch(CONTACT_COLOR)} contact point · {swatch(NORMAL_COLOR, '&#9472;')} surface normal (outward) · "
            f"{swatch(CONE_STYLE[0], '&#9650;')} friction cone (half-angle atan μ = {np.degrees(np.arctan(mu)):.0f}°)\n\n"
            f"Point set: faded, one colour per kd-tree leaf. Finger spheres: {spheres}")


def leaf_colors(leaves: np.ndarray) -> np.ndarray:
    """(m, 3) uint8: a distinct-looking colour per kd-tree leaf (golden-ratio hues, fixed saturation and value)."""
    hue = (leaves * 0.618033988749895) % 1.0
    k = (np.array([5.0, 3.0, 1.0])[None] + hue[:, None] * 6.0) % 6.0
    rgb = 0.9 - 0.9 * 0.75 * np.clip(np.minimum(k, 4.0 - k), 0.0, 1.0)
    return (rgb * 255).astype(np.uint8)


def friction_cones(points: np.ndarray, normals: np.ndarray, mu: float, height: float = CONE_HEIGHT) -> trimesh.Trimesh:
    """One mesh of cones, apex at each contact, axis along the outward normal, half-angle atan(mu)."""
    parts = []
    for p, n in zip(points, normals):
        cone = trimesh.creation.cone(radius=height * mu, height=height, sections=16)  # base at z=0, apex at z=h
        flip = trimesh.transformations.rotation_matrix(np.pi, (1, 0, 0))
        flip[2, 3] = height  # apex to the origin, base at z=h
        T = trimesh.geometry.align_vectors((0, 0, 1), n)
        T[:3, 3] = p
        cone.apply_transform(T @ flip)
        parts.append(cone)
    return trimesh.util.concatenate(parts)


def spheres_mesh(centres: np.ndarray, radii: np.ndarray) -> trimesh.Trimesh:
    """One mesh of spheres."""
    return trimesh.util.concatenate([trimesh.creation.icosphere(subdivisions=1, radius=r).apply_translation(c)
                                     for c, r in zip(centres, radii)])


class GraspsLayer(StepLayer):
    """A grasp list on its object; which placement the object is drawn at is the subclass's `placement`."""

    placement = "initial"  # or "final": the scene's object pose the list is drawn at
    title = "Grasps"
    step = "pick_grasps"  # the step whose result it draws (its recorded parameters made the point set and workspaces)

    def __init__(self, server: viser.ViserServer, scene: Scene, root: str, workbench: Host | None = None,
                 session: Session | None = None):
        super().__init__(server, scene, root, workbench, session)
        self.rank: viser.GuiDropdownHandle | None = None
        self.show_points: viser.GuiCheckboxHandle | None = None
        self.show_spheres: viser.GuiCheckboxHandle | None = None
        self.scores: viser.GuiMarkdownHandle | None = None
        self.result: GraspList | None = None
        self.hand_model: HandModel | None = None
        self.hand: HandMeshes | None = None
        self.shown_rank: int | None = None
        self._points_handle: viser.PointCloudHandle | None = None
        self._sphere_handles: list[viser.MeshHandle] | None = None  # None: not drawn yet

    def update(self, result: GraspList) -> None:
        self.remove_folder()
        for handle in ([self._points_handle] if self._points_handle is not None else []) + (self._sphere_handles or []):
            handle.remove()  # another list's figures
        self._points_handle, self._sphere_handles = None, None
        self.result = result
        scene = self.scene
        wxyz, xyz = matrix_wxyz(self.object_pose)
        obj_node = f"{self.name}/object"
        self.server.scene.add_frame(obj_node, show_axes=False, wxyz=wxyz, position=xyz)
        hand = load_hand_model(hand_spec_of(scene.robot.spec, result.hand))
        self.hand_model = hand
        arms = scene.robot.spec.arm_names
        color = ARM_COLORS[arms.index(result.hand) % len(ARM_COLORS)] if result.hand in arms else HAND_STYLE[0]
        self.hand = HandMeshes(self.server, f"{obj_node}/hand", hand, color=color, opacity=1.0, visible=False)
        self._build_gui(result)
        self.poses = {}
        if len(result):
            self.show(0)

    def _build_gui(self, result: GraspList) -> None:
        gui = self.server.gui
        self.folder = gui.add_folder(f"{self.title}: {result.hand} hand")
        with self.folder:
            if len(result):
                labels = self.rank_labels(result)
                self.rank = gui.add_dropdown("Rank", labels, initial_value=labels[0], hint="Grasps best first: pick one to see it")
                self.rank.on_update(self._rank_chosen)
            self.show_points = gui.add_checkbox("Object point set", False, hint="The points the search placed fingertips on, "
                                                "coloured by kd-tree leaf")
            self.show_points.on_update(lambda _: self.set_points_visible(self.show_points.value))
            self.show_spheres = gui.add_checkbox("Finger sphere hierarchies", False)
            self.show_spheres.on_update(lambda _: self.set_spheres_visible(self.show_spheres.value))
            self.scores = gui.add_markdown(self.summary(result))
            gui.add_markdown(legend(result.mu, tuple(self.hand_model.finger_names) if self.hand_model is not None else ()))

    @property
    def object_pose(self) -> np.ndarray:
        """Where the list is drawn: the object's initial or final placement."""
        return np.asarray(self.scene.object_initial if self.placement == "initial" else self.scene.object_final, float)

    def _rank_chosen(self, event: viser.GuiEvent) -> None:
        """Show the chosen rank; chosen by a person, it first gets the focus (the rest dimmed, the object framed), so that
        a shown rank means a finished focus."""
        if event.client is not None and self.workbench is not None:
            self.workbench.focus_grasp(self.step, self.object_pose)
        self.show(self.rank_of(event.target.value))

    @staticmethod
    def rank_labels(result: GraspList) -> tuple[str, ...]:
        return tuple(f"{r + 1}: ε={result.epsilon[r]:.4f} quality={result.quality[r]:.3f}" for r in range(len(result)))

    @staticmethod
    def rank_of(label: str) -> int:
        return int(label.split(":", 1)[0]) - 1

    @staticmethod
    def summary(result: GraspList) -> str:
        return (f"{len(result)} grasps kept of {plain(result.frames_tried)} frames tried, μ={result.mu:g}, "
                f"{plain(result.cone_edges)} cone edges")

    def scores_text(self, rank: int) -> str:
        r = self.result
        assert r is not None
        rows = "\n".join(f"| {s} | {float(getattr(r, s)[rank]):.4f} |" for s in r.SCORES)
        fingers = ", ".join(plain(c["finger"]) for c in r.contacts(rank))
        return f"**Rank {rank + 1}** of {len(r)} — contacts: {fingers}\n\n| score | value |\n|---|---|\n{rows}\n\n{self.summary(r)}"

    def set_points_visible(self, visible: bool) -> None:
        """Show or hide the object's point set, asking the planner for it the first time it is shown."""
        if self._points_handle is None:
            if not visible:
                return
            assert self.result is not None
            model = object_points(self.scene.object_mesh, self.result, self.params_of(self.step))
            self._points_handle = self.server.scene.add_point_cloud(
                f"{self.name}/object/points", model.points.astype(np.float32),
                faint(leaf_colors(model.leaves), POINT_FADE),
                point_size=POINT_SIZE, point_shape="circle", precision="float32")
        self._points_handle.visible = visible

    def set_spheres_visible(self, visible: bool) -> None:
        """Show or hide the fingers' workspace spheres, asking the planner for them the first time they are shown."""
        if self._sphere_handles is None:
            if not visible:
                return
            hand = self.hand_model
            assert hand is not None
            self._sphere_handles = []
            for ws in finger_spheres(hand, self.params_of(self.step)):
                mesh = spheres_mesh(ws.centres, ws.radii)
                self._sphere_handles.append(self.server.scene.add_mesh_simple(
                    f"{self.name}/object/hand/spheres_{ws.finger}", mesh.vertices, mesh.faces,
                    color=FINGER_COLORS[hand.finger_names.index(ws.finger) % len(FINGER_COLORS)], opacity=SPHERE_OPACITY,
                    cast_shadow=False, receive_shadow=False))
        for h in self._sphere_handles:
            h.visible = visible

    def show(self, rank: int) -> None:
        """Draw the grasp at `rank` (0 = best): the hand at its pose and configuration, its contacts, normals and cones."""
        r = self.result
        assert r is not None and self.hand is not None
        obj_node = f"{self.name}/object"
        with self.server.atomic():
            self.hand.pose(r.hand_pose[rank], r.finger_q[rank])
            mask = r.contact_mask[rank]
            points, normals = r.contact_point[rank][mask], r.contact_normal[rank][mask]
            if len(points):
                dots = spheres_mesh(points, np.full(len(points), CONTACT_RADIUS))
                self.server.scene.add_mesh_simple(f"{obj_node}/contacts", dots.vertices, dots.faces, color=CONTACT_COLOR,
                                                  cast_shadow=False, receive_shadow=False)
                segments = np.stack([points, points + NORMAL_LENGTH * normals], axis=1)
                self.server.scene.add_line_segments(f"{obj_node}/normals", segments, NORMAL_COLOR, thickness=NORMAL_THICKNESS)
                cones = friction_cones(points, normals, r.mu)
                self.server.scene.add_mesh_simple(f"{obj_node}/cones", cones.vertices, cones.faces, color=CONE_STYLE[0],
                                                  opacity=CONE_STYLE[1], cast_shadow=False, receive_shadow=False)
        self.shown_rank = rank
        if self.scores is not None:
            self.scores.content = self.scores_text(rank)
        if self.rank is not None and self.rank_of(self.rank.value) != rank:
            self.rank.value = self.rank_labels(r)[rank]

    def remove_folder(self) -> None:
        super().remove_folder()
        self.rank = self.show_points = self.show_spheres = self.scores = None


class PickGraspsLayer(GraspsLayer):
    """The picking hand's list, on the object at its initial placement."""

    placement = "initial"
    title = "Pick grasps"


class PlaceGraspsLayer(GraspsLayer):
    """The placing hand's list, on the object at its final placement."""

    placement = "final"
    title = "Place grasps"
    step = "place_grasps"
