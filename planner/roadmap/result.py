"""The roadmap step's parameters and result: elementary roadmaps and Super Graph as numpy arrays."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.core.bounds import bounded, described
from planner.core.results import array


@dataclass(frozen=True)
class RoadmapParams:
    """How the offline roadmap is built (all part of its cache key)."""

    nodes: int = bounded(30, 2, 500, "nodes", "nodes per elementary roadmap of Vis-PRM (it stops there; task nodes are added)")
    radius: float = bounded(3.0, 0.01, 20.0, "rad", "a guard's visibility range (joint-space distance over a sub-system's joints)")
    max_failures: int = bounded(300, 1, 100000, "samples", "Vis-PRM also stops after this many useless samples in a row")
    env_padding: float = bounded(0.03, 0.001, 0.2, "m", "robot-obstacle pairs count as colliding closer than this at checks")
    env_clearance: float = bounded(0.01, 0.0, 0.2, "m", "robot-obstacle distance kept along every motion (between checks)")
    self_padding: float = bounded(
        0.015, 0.001, 0.2, "m", "robot-robot pairs count as colliding closer than this (and keep >= 0 between checks)")
    mixed_edges: bool = described(False, "also Super Graph edges whose common part switches source along two elementary edges")
    one_arm_edges: bool = described(True, "also Super Graph edges moving one arm along its elementary edge, the other still")
    both_arm_edges: bool = described(False, "also Super Graph edges moving both arms at once (the paper's; most of the build)")
    other_arm_edges: bool = described(True, "also Super Graph edges moving the arm whose common part the nodes do not take")
    switch_length: float = bounded(0.5, 0.0, 100.0, "rad", "Super Graph edges switching the common part's source: this near only")
    tree: bool = described(False, "the tree variant: Super Graph edges only between different connected components")
    task_nodes: int = bounded(60, 0, 2000, "nodes", "nodes added per elementary roadmap around the task's sites (0: Vis-PRM alone)")
    task_spread: float = bounded(0.25, 0.0, 3.0, "rad", "their Gaussian noise per joint around a site or a point between two")
    task_edge: float = bounded(1.0, 0.01, 20.0, "rad", "their longest edge to a nearer node (a query end joins them as cheaply)")
    task_neighbours: int = bounded(4, 1, 100, "edges", "edges joining each of them to its nearest nodes")
    site_starts: int = bounded(4, 0, 100, "IK starts", "random IK starts per site target around the initial configuration")
    bridge_attempts: int = bounded(200, 0, 10000, "edges", "nearest node pairs (within radius) tried to join a smaller component")

    def problem(self) -> str:
        """What is wrong between the values, naming the parameter ('' when nothing): checked before the step runs."""
        if self.env_clearance >= self.env_padding:
            return (f"env_clearance must be below env_padding ({self.env_padding:g} m): a padding is checked so that the clearance "
                    f"holds between checks, got {self.env_clearance:g} m")
        return ""


@dataclass(frozen=True)
class Roadmap:
    """Per-arm Vis-PRM roadmaps and their Super Graph (paper V-A).

    Elementary nodes are full configurations (the other arm and the hands at the hold configuration);
    `elem_arm` says whose roadmap each belongs to. A Super Graph node is the pair `node_elem` (one
    elementary node per arm, in `arms` order) with the common part from arm `node_common`. `wrists`
    holds each node's two wrist positions (the hands' mount frames), for drawing. Edges carry their
    joint-space length and a validity flag, so a later phase can mark them invalid.
    """

    arms: list
    resolution: dict
    checks: dict  # stage -> collision checks
    candidates: dict  # 'nodes' / 'edges' -> how many were tested
    vis_prm_samples: dict  # arm -> samples drawn
    elem_q: np.ndarray = array("float64", ("ne", "nq"))
    elem_arm: np.ndarray = array("int8", ("ne",))
    elem_guard: np.ndarray = array("bool", ("ne",))
    elem_edges: np.ndarray = array("int64", ("me", 2))
    node_q: np.ndarray = array("float64", ("n", "nq"))
    node_elem: np.ndarray = array("int64", ("n", 2))
    node_common: np.ndarray = array("int8", ("n",))
    node_component: np.ndarray = array("int64", ("n",))
    wrists: np.ndarray = array("float64", ("n", 2, 3))
    edges: np.ndarray = array("int64", ("m", 2))
    edge_length: np.ndarray = array("float64", ("m",))
    edge_valid: np.ndarray = array("bool", ("m",))

    def elementary(self, arm: str) -> tuple[np.ndarray, np.ndarray]:
        """(node ids into elem_q, edges as node id pairs) of one arm's elementary roadmap."""
        a = self.arms.index(arm)
        ids = np.flatnonzero(self.elem_arm == a)
        return ids, self.elem_edges[self.elem_arm[self.elem_edges[:, 0]] == a]

    def stats(self) -> dict:
        return {
            "nodes": int(len(self.node_q)),
            "edges": int(len(self.edges)),
            "components": int(len(np.unique(self.node_component))),
            "largest_component": int(np.bincount(self.node_component).max(initial=0)),
            "collision_checks": int(sum(self.checks.values())),
            "elementary_nodes": {a: int(np.sum(self.elem_arm == i)) for i, a in enumerate(self.arms)},
            "elementary_edges": {a: int(len(self.elementary(a)[1])) for a in self.arms},
            "candidate_nodes": int(self.candidates["nodes"]),
            "candidate_edges": int(self.candidates["edges"]),
            "stage_checks": {k: int(v) for k, v in self.checks.items()},
            "resolution": self.resolution,
        }


def render_stats(stats: dict, seconds: dict[str, float]) -> str:
    """The statistics table of `Roadmap.stats()` and the `seconds` of each stage built (none from the cache), for `regrasp roadmap`."""
    lines = [f"{name:<22}{stats[key]:>12}" for name, key in (("nodes", "nodes"), ("edges", "edges"), ("components", "components"),
                                                          ("largest component", "largest_component"),
                                                          ("collision checks", "collision_checks"))]
    for arm, n in stats["elementary_nodes"].items():
        lines.append(f"{'elementary ' + arm:<22}{n:>12} nodes {stats['elementary_edges'][arm]:>6} edges")
    for stage, checks in stats["stage_checks"].items():
        time = f"{seconds[stage]:>12.2f}" if seconds else f"{'(cached)':>12}"
        lines.append(f"{stage + ' (s)':<22}{time} {checks:>12} checks")
    if seconds:
        lines.append(f"{'total (s)':<22}{sum(seconds.values()):>12.2f}")
    res = stats["resolution"]
    lines.append(f"resolution: {res['bound']}: {res['obstacle_step_m']} m to obstacles, {res['robot_step_m']} m to the robot")
    return "\n".join(lines)
