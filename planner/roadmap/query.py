"""Offline queries on the Super Graph: connect two configurations with straight lines, then Dijkstra.

`Graph` is a mutable working copy of a roadmap's graph (nodes can be added, edges added or marked
invalid) for the online phases; `RoadmapPlanner` answers queries on it. Every segment of a returned
path passed the roadmap's local planner at its stated resolution.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from planner.model.task import Scene
from planner.roadmap.build import roadmap_collision_model, segment_checker
from planner.roadmap.result import Roadmap, RoadmapParams


class Graph:
    """Nodes (configurations) and undirected weighted edges with a validity flag, as numpy arrays."""

    def __init__(self, q: np.ndarray, edges: np.ndarray, valid: np.ndarray):
        self.q = np.array(q, dtype=float)
        self.edges = np.array(edges, dtype=np.int64).reshape(-1, 2)
        self.valid = np.array(valid, dtype=bool)

    @staticmethod
    def from_roadmap(roadmap: Roadmap) -> "Graph":
        return Graph(roadmap.node_q, roadmap.edges, roadmap.edge_valid)

    def add_nodes(self, q: np.ndarray) -> np.ndarray:
        """Append configurations; returns their node ids."""
        q = np.atleast_2d(q)
        self.q = np.concatenate([self.q, q])
        return np.arange(len(self.q) - len(q), len(self.q))

    def add_edges(self, pairs: np.ndarray) -> np.ndarray:
        """Append (valid) edges between node ids; returns their edge ids."""
        pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
        self.edges = np.concatenate([self.edges, pairs])
        self.valid = np.concatenate([self.valid, np.ones(len(pairs), dtype=bool)])
        return np.arange(len(self.edges) - len(pairs), len(self.edges))

    def invalidate(self, edge_ids: np.ndarray) -> None:
        """Mark edges invalid: searches no longer use them."""
        self.valid[np.asarray(edge_ids, dtype=np.int64)] = False

    def shortest_path(self, source: int, target: int) -> list[int] | None:
        """Node ids of a shortest path over the valid edges (joint-space length), or None."""
        e = self.edges[self.valid]
        return shortest_path(len(self.q), e, np.linalg.norm(self.q[e[:, 0]] - self.q[e[:, 1]], axis=1), source, target)


def shortest_path(n: int, edges: np.ndarray, weights: np.ndarray, source: int, target: int) -> list[int] | None:
    """Node ids of a shortest path (Dijkstra) over undirected weighted edges among n nodes, or None."""
    # a zero-length edge would vanish from a sparse matrix: weigh every edge at least a tiny bit
    graph = coo_matrix((np.maximum(weights, 1e-12), (edges[:, 0], edges[:, 1])), shape=(n, n)).tocsr()
    dist, pred = dijkstra(graph, directed=False, indices=source, return_predecessors=True)
    if not np.isfinite(dist[target]):
        return None
    path = [target]
    while path[-1] != source:
        path.append(int(pred[path[-1]]))
    return path[::-1]


@dataclass(frozen=True)
class QueryResult:
    """A joint-space path (its every segment checked), the graph nodes it visits, and the work done."""

    found: bool
    path: np.ndarray  # (k, nq), from the start to the goal; empty when not found
    nodes: list  # Super Graph node ids along the path
    length: float
    checks: int
    message: str = ""


class RoadmapPlanner:
    """Queries on one roadmap, checked with the collision model and resolution it was built with."""

    def __init__(self, scene: Scene, roadmap: Roadmap, params: RoadmapParams = RoadmapParams()):
        cm, self.dec = roadmap_collision_model(scene, params)
        self.seg = segment_checker(cm, params)
        self.roadmap = roadmap
        self.graph = Graph.from_roadmap(roadmap)

    def _connections(self, q: np.ndarray, candidates: int, connections: int) -> list[int]:
        """Roadmap nodes (of the first `len(roadmap.node_q)`) reachable from q by a free straight line, nearest first."""
        roadmap_q = self.graph.q[: len(self.roadmap.node_q)]
        found: list[int] = []
        for k in np.argsort(np.linalg.norm(roadmap_q - q, axis=1))[:candidates]:
            if self.seg.segment_free(q, roadmap_q[k], "moving", ends=False):
                found.append(int(k))
                if len(found) == connections:
                    break
        return found

    def query(self, q_start: np.ndarray, q_goal: np.ndarray, candidates: int = 30, connections: int = 5) -> QueryResult:
        """A collision-free path from q_start to q_goal through the Super Graph (or a direct line)."""
        before = self.seg.checks
        for name, q in (("start", q_start), ("goal", q_goal)):
            held = np.setdiff1d(np.arange(len(q)), self.dec.transit)
            if not np.allclose(q[held], self.dec.q_hold[held]):
                raise ValueError(f"the {name} configuration moves joints the roadmap holds fixed (the hands): transit only")
            if not self.seg.free(q, "moving"):
                return self._fail(before, f"the {name} configuration collides (with the roadmap's paddings)")
        if self.seg.segment_free(q_start, q_goal, "moving", ends=False):
            path = np.stack([q_start, q_goal])
            return QueryResult(True, path, [], _length(path), self.seg.checks - before)
        ends = []
        for name, q in (("start", q_start), ("goal", q_goal)):
            near = self._connections(q, candidates, connections)
            if not near:
                return self._fail(before, f"no straight line from the {name} to any of its {candidates} nearest roadmap nodes")
            ends.append((q, near))
        graph = self.graph
        n_edges = len(graph.edges)
        ids = graph.add_nodes(np.stack([q_start, q_goal]))
        graph.add_edges([(i, k) for i, (_, near) in zip(ids, ends) for k in near])
        try:
            nodes = graph.shortest_path(int(ids[0]), int(ids[1]))
        finally:
            graph.q, graph.edges, graph.valid = graph.q[: ids[0]], graph.edges[:n_edges], graph.valid[:n_edges]
        if nodes is None:
            return self._fail(before, "start and goal connect to different components of the Super Graph")
        path = np.concatenate([[q_start], self.graph.q[nodes[1:-1]], [q_goal]])
        return QueryResult(True, path, nodes[1:-1], _length(path), self.seg.checks - before)

    def _fail(self, before: int, message: str) -> QueryResult:
        return QueryResult(False, np.zeros((0, len(self.dec.q_hold))), [], 0.0, self.seg.checks - before, message)


def _length(path: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())
