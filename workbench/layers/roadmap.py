"""The `roadmap` step drawn: the Super Graph in wrist space, node picking and a query tool that animates its path.

Each wrist's moves along the Super Graph's edges are drawn, from its position at one node to its
position at the other, a move that several edges share once (all segments in one `add_line_segments`
call: viser is slow to show thousands of separate nodes). A wrist has its arm's colour; the largest
components get shades of it, the small ones are grey, invalid edges dark. The "Roadmap" GUI folder
picks a node (the robot goes there) and asks the planner's Super Graph query (`motion.query`, the motion's
graph and transit for the robot alone) for a path from the workbench's current configuration to it, in a
background thread, then animates.
"""
from __future__ import annotations

import colorsys
import threading
import time

import numpy as np
import viser

from planner.core.plain_text import plain
from planner.core.session import Session
from planner.model.task import Scene
from planner.motion.query import QueryResult, RoadmapQuery
from planner.roadmap.build import wrist_positions
from planner.roadmap.result import Roadmap

from ..notify import error_text
from .arms import ARM_COLORS
from .base import Host, Pose, StepLayer

SHADES = (1.0, 0.55, 1.45, 0.8)  # brightness of the wrist's colour for the 1st, 2nd, ... largest component
SMALL_COLOR = (150, 150, 150)  # components beyond SHADES
INVALID_COLOR = (60, 60, 60)  # edges marked invalid
LINE_THICKNESS = 0.0012  # m: thin and ...
FAINT = 0.6  # ... faded this far toward the background, so the Super Graph never hides the robot and the object
BACKGROUND = 245  # the viewer's near-white background, per channel
ARM_COLOR_NAMES = ("blue", "orange", "green", "purple")  # of ARM_COLORS
MARK_RADIUS = 0.025  # m: the chosen node's wrists
MARK_COLOR = (250, 20, 160)
FPS = 30.0
WRIST_STEP = 0.03  # m: the largest wrist move between two animation frames ...
JOINT_STEP = 0.05  # rad: ... and the largest joint move (for the torso, which moves the wrists little but the body a lot)
MOVE_BUDGET = 600  # wrist moves drawn at first: software WebGL redraws every line each frame, so the page stays responsive
SHOWN = ("every component", "the largest component", "the chosen node's component")  # whose moves are drawn


def _shade(color: tuple[int, int, int], factor: float) -> tuple[int, int, int]:
    h, light, s = colorsys.rgb_to_hls(*(c / 255 for c in color))
    r, g, b = colorsys.hls_to_rgb(h, min(1.0, light * factor), s)
    return int(r * 255), int(g * 255), int(b * 255)


def faint(colors: np.ndarray, amount: float = FAINT) -> np.ndarray:
    """uint8 colours faded toward the background by `amount` (0: as they are, 1: the background)."""
    return np.round(colors + amount * (BACKGROUND - colors.astype(float))).astype(np.uint8)


def edge_component_rank(roadmap: Roadmap) -> np.ndarray:
    """(edges,) the size rank of each edge's component: 0 for the largest."""
    comp = roadmap.node_component
    sizes = np.bincount(comp)
    rank = np.empty_like(sizes)
    rank[np.argsort(-sizes, kind="stable")] = np.arange(len(sizes))
    return rank[comp[roadmap.edges[:, 0]]] if len(roadmap.edges) else np.zeros(0, dtype=int)


def edge_colors(roadmap: Roadmap) -> np.ndarray:
    """(edges, wrists, 3) uint8: each wrist's colour shaded by its edge's component rank; grey for small ones, dark if invalid."""
    edge_rank = edge_component_rank(roadmap)
    wrists = roadmap.wrists.shape[1]
    out = np.empty((len(roadmap.edges), wrists, 3), dtype=np.uint8)
    for w in range(wrists):
        palette = np.array([_shade(ARM_COLORS[w % len(ARM_COLORS)], f) for f in SHADES] + [SMALL_COLOR], dtype=np.uint8)
        out[:, w] = palette[np.minimum(edge_rank, len(SHADES))]
    out[~roadmap.edge_valid] = INVALID_COLOR
    return out


def wrist_segments(roadmap: Roadmap) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """((k, 2, 3) segments, (k, 3) uint8 colours, (k,) the edge of each): each wrist's moves along the Super Graph's
    edges, each drawn once.

    A wrist that holds still (one-arm edge) draws nothing, and a move that several edges share (the same elementary
    edge with the other arm anywhere) is drawn once, in the colour of its most
    prominent edge (valid before invalid, then the largest component): software WebGL draws every line it is sent.
    """
    wrists = roadmap.wrists.shape[1]
    points = roadmap.wrists[roadmap.edges].transpose(0, 2, 1, 3).reshape(-1, 2, 3)  # (edges * wrists, 2 ends, 3)
    colors = edge_colors(roadmap).reshape(-1, 3)
    rank = edge_component_rank(roadmap)
    priority = np.repeat(rank + np.where(roadmap.edge_valid, 0, len(rank) + 1), wrists)
    a, b = points[:, 0], points[:, 1]
    moved = np.flatnonzero(np.any(a != b, axis=1))
    first = np.argmax(a[moved] != b[moved], axis=1)  # the first coordinate where the ends differ orders them
    swap = a[moved, first] > b[moved, first]
    keys = np.where(swap[:, None, None], points[moved][:, ::-1], points[moved]).reshape(len(moved), 6)
    order = np.argsort(priority[moved], kind="stable")
    _, firsts = np.unique(keys[order], axis=0, return_index=True)
    kept = moved[np.sort(order[firsts])]
    return points[kept], colors[kept], kept // wrists


def spread(n: int, budget: int) -> np.ndarray:
    """At most `budget` of the indices 0..n-1, evenly spread over them (the first and last included)."""
    if n <= budget:
        return np.arange(n)
    return np.unique(np.round(np.linspace(0, n - 1, max(budget, 1))).astype(np.int64))


def frames(robot, path: np.ndarray) -> np.ndarray:
    """The path resampled for animation: straight joint-space lines, at most WRIST_STEP of wrist and JOINT_STEP of joint motion a frame."""
    if len(path) < 2:
        return path
    w = wrist_positions(robot, path)
    out = [path[:1]]
    for k in range(len(path) - 1):
        n = int(max(1, np.ceil(np.linalg.norm(w[k + 1] - w[k], axis=1).max() / WRIST_STEP),
                    np.ceil(np.abs(path[k + 1] - path[k]).max() / JOINT_STEP)))
        t = np.linspace(0.0, 1.0, n + 1)[1:, None]
        out.append(path[k] + t * (path[k + 1] - path[k]))
    return np.concatenate(out)


class RoadmapLayer(StepLayer):
    """The Super Graph in wrist space, a chosen node, and planning to it from the robot's current configuration."""

    def __init__(self, server: viser.ViserServer, scene: Scene, root: str, workbench: Host | None = None,
                 session: Session | None = None):
        super().__init__(server, scene, root, workbench, session)
        self.roadmap: Roadmap | None = None
        self.last_query: QueryResult | None = None
        self.job: threading.Thread | None = None
        self._query: RoadmapQuery | None = None
        self._plan_lock = threading.Lock()
        self._animation = 0  # bumped to stop a running animation
        self._moves: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # `wrist_segments` of the roadmap
        self._edges: viser.LineSegmentsHandle | None = None
        self.chosen = 0  # the node marked

    # -- drawing ---------------------------------------------------------------------------------

    def update(self, result: Roadmap) -> None:
        self.roadmap, self._query, self.last_query = result, None, None
        self._moves = wrist_segments(result) if len(result.edges) else None
        stats = result.stats()
        self._build_gui(stats)
        largest = int(np.argmax(np.bincount(result.node_component))) if len(result.node_q) else 0
        self.poses = {}
        if len(result.node_q):
            first = int(np.flatnonzero(result.node_component == largest)[0])
            self.poses = {f"roadmap: node {first} (largest component)": Pose(result.node_q[first], self.scene.object_initial)}
            self.mark(first)
        self.draw_moves()

    def _build_gui(self, stats: dict) -> None:
        gui = self.server.gui
        n = max(1, stats["nodes"])
        moves = len(self._moves[0]) if self._moves is not None else 0
        with gui.add_folder("Roadmap") as self.folder:
            gui.add_markdown(f"Super Graph: **{plain(stats['nodes'])}** nodes, **{plain(stats['edges'])}** edges, "
                             f"**{plain(stats['components'])}** components (largest {plain(stats['largest_component'])}); "
                             + ", ".join(f"{plain(a)} wrist: {c}" for a, c in zip(self.roadmap.arms, ARM_COLOR_NAMES)))
            self.shown_of = gui.add_dropdown("Moves of", SHOWN, hint="Whose wrist moves are drawn")
            self.budget = gui.add_slider("Moves drawn", min=min(100, max(moves, 1)), max=max(moves, 1), step=max(1, moves // 100),
                                         initial_value=min(MOVE_BUDGET, max(moves, 1)),
                                         hint="At most this many wrist moves, evenly spread (more draw slower in the browser)")
            self.drawn = gui.add_markdown("")
            self.node = gui.add_slider("Node", min=0, max=n - 1, step=1, initial_value=0,
                                       hint="A Super Graph node: the robot goes there")
            self.go_button = gui.add_button("Robot to node")
            self.plan_button = gui.add_button("Plan to node", hint="Plan from the current configuration (hands at rest) and animate")
            self.status = gui.add_markdown("")
        self.shown_of.on_update(lambda _: self.draw_moves())
        self.budget.on_update(lambda _: self.draw_moves())
        self.node.on_update(lambda e: self.pick(int(e.target.value)))
        self.go_button.on_click(lambda _: self.pick(int(self.node.value)))
        self.plan_button.on_click(lambda _: self.plan_to(int(self.node.value)))

    def moves_drawn(self) -> np.ndarray:
        """The indices of the wrist moves drawn: those of the components chosen in "Moves of", at most "Moves drawn" of
        them, evenly spread."""
        assert self.roadmap is not None and self._moves is not None
        roadmap, edge = self.roadmap, self._moves[2]
        component = roadmap.node_component[roadmap.edges[edge, 0]]
        if self.shown_of.value == SHOWN[1]:
            candidates = np.flatnonzero(component == np.argmax(np.bincount(roadmap.node_component)))
        elif self.shown_of.value == SHOWN[2]:
            candidates = np.flatnonzero(component == roadmap.node_component[self.chosen])
        else:
            candidates = np.arange(len(edge))
        return candidates[spread(len(candidates), int(self.budget.value))]

    def draw_moves(self) -> None:
        """(Re)draw the wrist moves `moves_drawn` picks, and say how many of how many are drawn."""
        if self._moves is None:
            self.drawn.content = "*No edges to draw.*"
            return
        points, colors, _ = self._moves
        drawn = self.moves_drawn()
        if self._edges is not None:
            self._edges.remove()
            self._edges = None
        if len(drawn):
            self._edges = self.server.scene.add_line_segments(f"{self.name}/edges", points[drawn].astype(np.float32),
                                                              np.repeat(faint(colors[drawn])[:, None], 2, axis=1),
                                                              thickness=LINE_THICKNESS)
        self.drawn.content = f"Drawn: **{len(drawn)}** of {len(points)} wrist moves."

    def mark(self, i: int) -> None:
        """Mark node i: a sphere at each of its wrists and a label; with "the chosen node's component", its moves are drawn."""
        assert self.roadmap is not None
        redraw = self.chosen != i and self.shown_of.value == SHOWN[2]
        self.chosen = i
        if redraw:
            self.draw_moves()
        for w, p in enumerate(self.roadmap.wrists[i]):
            self.server.scene.add_icosphere(f"{self.name}/mark/w{w}", radius=MARK_RADIUS, color=MARK_COLOR, position=p,
                                            cast_shadow=False, receive_shadow=False)
        top = self.roadmap.wrists[i].mean(axis=0) + (0.0, 0.0, 0.15)
        self.server.scene.add_label(f"{self.name}/mark/label", f"node {i} (component {int(self.roadmap.node_component[i])})",
                                    position=top, anchor="bottom-center")

    # -- the workbench's robot -------------------------------------------------------------------

    def _say(self, text: str) -> None:
        if self.folder is not None:
            self.status.content = text

    def pick(self, i: int) -> None:
        """Mark node i and put the robot there."""
        if self.roadmap is None or not 0 <= i < len(self.roadmap.node_q):
            return
        self._animation += 1
        self.mark(i)
        wb = self.workbench
        if wb is None:
            return
        wb.pose_robot(self.roadmap.node_q[i], self.scene.object_initial, f"roadmap: node {i}")
        self._say(f"Robot at node {i} (component {int(self.roadmap.node_component[i])}).")

    def plan_to(self, i: int) -> threading.Thread | None:
        """In the background: plan from the workbench's configuration (hands at rest) to node i, then animate the path."""
        wb = self.workbench
        if self.roadmap is None or wb is None:
            return None
        if self.job is not None and self.job.is_alive():
            self._say("*Already planning: wait for the current query.*")
            return None
        self._animation += 1
        self.mark(i)
        self.job = threading.Thread(target=self._plan, args=(wb, i, np.array(wb.q, dtype=float), self._animation), daemon=True)
        self.job.start()
        return self.job

    def _plan(self, wb: Host, i: int, q: np.ndarray, animation: int) -> None:
        roadmap = self.roadmap
        assert roadmap is not None
        try:
            with self._plan_lock:
                if self._query is None:
                    self._query = RoadmapQuery(self.scene, roadmap, self.params_of("roadmap"))
                q, moved = self._query.at_rest(q)
                self._say(f"*Planning to node {i}…* (the first query builds the roadmap's collision model)")
                t0 = time.monotonic()
                result = self._query.query(q, roadmap.node_q[i])
        except Exception as exc:  # shown, never raised into viser's thread
            self._say(f"<span style='color:#d22'>**Query failed:** {plain(error_text(exc))}</span>")
            return
        self.last_query = result
        note = " (hands put at rest first)" if moved else ""
        if not result.found:
            self._say(f"<span style='color:#d22'>**No path** to node {i}{note}: {plain(result.message)}</span>")
            return
        self._say(f"**Path found** to node {i}{note}: {len(result.path)} waypoints, length {result.length:.2f} rad, "
                  f"{result.checks} checks, {time.monotonic() - t0:.1f} s. *Animating…*")
        self._animate(wb, frames(self.scene.robot, result.path), animation, f"roadmap: path to node {i}")
        if animation == self._animation:
            self._say(f"**Path found** to node {i}{note}: {len(result.path)} waypoints, length {result.length:.2f} rad, "
                      f"{result.checks} checks. Robot at node {i}.")

    def _animate(self, wb: Host, qs: np.ndarray, animation: int, label: str) -> None:
        """Pose the robot at each of qs, at most FPS a second (slower when drawing is); stops when another action starts."""
        start = time.monotonic()
        for k, q in enumerate(qs):
            if animation != self._animation:
                return
            time.sleep(max(0.0, start + k / FPS - time.monotonic()))
            wb.pose_robot(q, self.scene.object_initial, label)

    # -- removal ---------------------------------------------------------------------------------

    def remove(self) -> None:
        self._animation += 1  # a running animation stops at its next frame
        super().remove()
