"""Transit queries for the robot alone on the Super Graph: the workbench's "Plan to node" tool.

The same graph and query as the motion's transits (`MotionGraph`, `LazyTransit`), checked with the
roadmap's own collision model and local planner: the robot alone, the hands at the roadmap's hold
values, so nothing differs from what the offline roadmap validated ('changed' is empty) and only the
connections and reconnections are checked. Every segment of a returned path passed the roadmap's
local planner at its stated resolution. Each query works on its own copy of the graph. The collision
model and the graph are built at the first query: a service made for a replayed session costs nothing.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from planner.collision.validity import Validity, transit_profile
from planner.model.task import Scene
from planner.motion.graph import MotionGraph
from planner.motion.result import MotionParams
from planner.motion.space import JointSpace
from planner.motion.transit import LazyTransit, TransitFailed, TransitParams, TransitStats
from planner.roadmap.build import resolution, roadmap_collision_model, segment_checker
from planner.roadmap.decomposition import decompose
from planner.roadmap.result import Roadmap, RoadmapParams


@dataclass(frozen=True)
class QueryResult:
    """A joint-space path (its every segment checked) and the work done; `message` says why none was found."""

    found: bool
    path: np.ndarray  # (k, nq), from the start to the goal; empty when not found
    length: float  # joint-space length
    checks: int
    message: str = ""


class RoadmapQuery:
    """Queries on one roadmap for the robot alone, with the collision model and resolution it was built with."""

    def __init__(self, scene: Scene, roadmap: Roadmap, params: RoadmapParams = RoadmapParams(),
                 transit: TransitParams = TransitParams.of(MotionParams()), seed: int = 0):
        self.scene, self.roadmap, self.params, self.transit, self.seed = scene, roadmap, params, transit, seed
        dec = decompose(scene.robot)
        self.space = JointSpace.of(scene.robot.lower, scene.robot.upper, dec.transit, dec.q_hold)

    @functools.cached_property
    def validity(self) -> Validity:
        """The roadmap's local planner over its moving pairs; 'changed' (what a roadmap element needs checking again) is
        empty: the robot alone is what the roadmap validated."""
        cm, _ = roadmap_collision_model(self.scene, self.params)
        profile = transit_profile(resolution(self.params), self.params.env_padding, self.params.self_padding)
        return Validity(segment_checker(cm.with_subsets({"changed": np.zeros(0, np.int64)}), self.params), profile, "moving")

    @functools.cached_property
    def graph(self) -> MotionGraph:
        return MotionGraph(self.roadmap)

    def at_rest(self, q: np.ndarray) -> tuple[np.ndarray, bool]:
        """q with the hands put at the roadmap's hold values (where its queries may start), and whether that moved them."""
        return self.space.full(self.space.reduce(q)), not self.space.holds(q)

    def query(self, q_start: np.ndarray, q_goal: np.ndarray) -> QueryResult:
        """A valid path from q_start to q_goal through the Super Graph (or a direct line), RRTConnect bridging what the
        graph cannot; both must hold the hands at the roadmap's values (transit only)."""
        full = self.validity
        before = full.checks
        for name, q in (("start", q_start), ("goal", q_goal)):
            if not self.space.holds(q):
                raise ValueError(f"the {name} configuration moves joints the roadmap holds fixed (the hands): transit only")
            if not full.state_valid(q):
                return self._fail(before, f"the {name} configuration collides (with the roadmap's paddings)")
        transit = LazyTransit(self.graph.copy(), self.space, full.on("changed"), full, full, self.transit,
                              np.random.default_rng(self.seed), TransitStats())
        try:
            path = transit.query(np.asarray(q_start, float), np.asarray(q_goal, float))
        except TransitFailed as exc:
            return self._fail(before, str(exc))
        length = float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())
        return QueryResult(True, path, length, full.checks - before)

    def _fail(self, before: int, message: str) -> QueryResult:
        return QueryResult(False, np.zeros((0, len(self.space.base))), 0.0, self.validity.checks - before, message)
