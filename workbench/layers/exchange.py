"""The `exchange` step drawn (paper V-C, fig. 6): the cheapest free grid nodes as one point cloud coloured by cost (yellow
cheap, purple expensive; blocked nodes hidden; a slider sets the share shown, as the whole grid would hide the robot), a
sphere at the chosen exchange position, and each palm's route through it: picking palm initial -> grasp -> exchange ->
final, placing palm initial -> exchange -> place -> final."""
from __future__ import annotations

import numpy as np
import viser

from planner.core.session import Session
from planner.handover.exchange import Exchange
from planner.model.task import Scene

from .arms import ARM_COLORS
from .base import Host, StepLayer
from .stages import stages_markdown

COLORMAP = np.array([(253, 231, 37), (94, 201, 98), (33, 145, 140), (59, 82, 139), (68, 1, 84)], float)  # viridis, reversed
NODE_SIZE = 0.012  # m: a grid node (the grid step is several times larger, so the cloud stays see-through)
BEST_RADIUS = 0.035  # m
BEST_COLOR = (250, 20, 160)
RUNNER_UP_SIZE = 0.03  # m: the other kept nodes
WAYPOINT_SIZE = 0.03  # m
ROUTE_THICKNESS = 0.006  # m
SHOWN_PERCENT = 10  # the cheapest free nodes drawn at first, % of them


def cost_colors(cost: np.ndarray) -> np.ndarray:
    """(k, 3) uint8: COLORMAP over the cost range, cheapest first."""
    span = np.ptp(cost) if len(cost) else 0.0
    t = (cost - cost.min()) / span if span > 0 else np.zeros_like(cost)
    x = t * (len(COLORMAP) - 1)
    i = np.minimum(x.astype(int), len(COLORMAP) - 2)
    f = (x - i)[:, None]
    return ((1 - f) * COLORMAP[i] + f * COLORMAP[i + 1]).astype(np.uint8)


def palm_routes(waypoints: np.ndarray, exchange: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(3, 2, 3) segments of each palm's route through the exchange position (fig. 6): picking, then placing palm."""
    pi, pg, pf, qi, qp, qf = waypoints
    picking = np.array([[pi, pg], [pg, exchange], [exchange, pf]])
    placing = np.array([[qi, exchange], [exchange, qp], [qp, qf]])
    return picking, placing


class ExchangeLayer(StepLayer):
    """The exchange grid by cost, the best exchange position and the palms' routes through it."""

    def __init__(self, server: viser.ViserServer, scene: Scene, root: str, workbench: Host | None = None,
                 session: Session | None = None):
        super().__init__(server, scene, root, workbench, session)
        self.result: Exchange | None = None
        self.shown: viser.GuiSliderHandle | None = None

    def update(self, result: Exchange) -> None:
        self.remove_folder()
        self.result = result
        scene = self.server.scene
        if len(result.best):
            best = result.position
            scene.add_icosphere(f"{self.name}/best", radius=BEST_RADIUS, color=BEST_COLOR, position=best,
                                cast_shadow=False, receive_shadow=False)
            scene.add_label(f"{self.name}/best/label", f"exchange: cost {result.cost[result.best[0]]:.2f}",
                            position=(0.0, 0.0, 2 * BEST_RADIUS), anchor="bottom-center")
            if len(result.best) > 1:
                scene.add_point_cloud(f"{self.name}/runners_up", result.nodes[result.best[1:]].astype(np.float32), BEST_COLOR,
                                      point_size=RUNNER_UP_SIZE, point_shape="circle", precision="float32")
            self._draw_routes(result, best)
        self.folder = self.server.gui.add_folder("Exchange position")
        with self.folder:
            where = f"at ({', '.join(f'{v:.2f}' for v in result.position)}) m" if len(result.best) else "none"
            grid = (f"{len(result.nodes)} nodes both hands reach ({result.step:g} m grid), {int(result.free.sum())} free; "
                    f"yellow = cheap, purple = expensive. Best exchange position (pink) {where}.")
            direct = not result.shoulders and not result.failure  # no grid was made: one arm picks and places
            self.server.gui.add_markdown(("No exchange: one arm carries the object itself." if direct else grid) + "\n\n"
                                         + stages_markdown(result.stages, result.failure))
            self.shown = self.server.gui.add_slider("Cheapest nodes (%)", min=1, max=100, step=1, initial_value=SHOWN_PERCENT,
                                                    hint="The share of the free nodes drawn, cheapest first")
        self.shown.on_update(lambda e: self.show_cheapest(e.target.value))
        self.show_cheapest(SHOWN_PERCENT)

    def show_cheapest(self, percent: float) -> None:
        """Draw the cheapest `percent` % of the free nodes, coloured over their cost range."""
        r = self.result
        free = np.flatnonzero(r.free) if r is not None else []
        if not len(free):
            return
        shown = free[np.argsort(r.cost[free], kind="stable")[: int(np.ceil(len(free) * percent / 100))]]
        self.server.scene.add_point_cloud(f"{self.name}/nodes", r.nodes[shown].astype(np.float32), cost_colors(r.cost[shown]),
                                          point_size=NODE_SIZE, point_shape="circle", precision="float32")

    def _draw_routes(self, result: Exchange, exchange: np.ndarray) -> None:
        """Each palm's waypoints and route in its arm's colour."""
        configs = self.earlier("grasp_configs")
        arms = self.scene.robot.spec.arm_names
        for route, arm, points in zip(("picking", "placing"), (configs.picking_arm, configs.placing_arm),
                                      palm_routes(result.waypoints, exchange)):
            color = ARM_COLORS[arms.index(arm) % len(ARM_COLORS)]
            self.server.scene.add_line_segments(f"{self.name}/{route}/route", points.astype(np.float32), color,
                                                thickness=ROUTE_THICKNESS)
            stops = np.vstack([points[:, 0], points[-1:, 1]])
            self.server.scene.add_point_cloud(f"{self.name}/{route}/waypoints", stops.astype(np.float32), color,
                                              point_size=WAYPOINT_SIZE, point_shape="circle", precision="float32")
