"""The Super Graph as the online phases use it: the offline roadmap plus what the phases add, with per-phase edge status.

Offline, every node and edge was validated for the robot alone with open hands (`offline`).
Online, each phase has its own validity, so each phase keeps its own status of nodes and edges
(unknown, valid, invalid): lazy revalidation marks them as it checks, and edges added by the RRT
reconnection stay in the graph (as edges nobody validated offline) for the rest of that phase's
transit, as the paper enriches its PRM with RRT trees. Each phase's transit works on its own copy of
the graph: the four are planned at once, in parallel.
"""
from __future__ import annotations

import copy

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components, dijkstra

from planner.core.results import frozen
from planner.motion.space import JointSpace
from planner.roadmap.result import Roadmap

UNKNOWN, VALID, INVALID = 0, 1, -1


class MotionGraph:
    """Nodes (full configurations, hands at the roadmap's hold values), edges, and which edges were validated offline."""

    def __init__(self, roadmap: Roadmap):
        self.q = np.array(roadmap.node_q, dtype=float)
        keep = np.asarray(roadmap.edge_valid, dtype=bool)
        self.edges = np.array(roadmap.edges, dtype=np.int64)[keep].reshape(-1, 2)
        self.offline = np.ones(len(self.edges), dtype=bool)
        self.n_roadmap, self.n_roadmap_edges = len(self.q), len(self.edges)
        self.index = dict(zip(map(tuple, np.sort(self.edges, axis=1).tolist()), range(len(self.edges))))  # _key of each edge
        self._roadmap_weights: dict[bytes, np.ndarray] = {}  # per space's coordinates: the roadmap's edges' lengths

    def weights(self, space: JointSpace) -> np.ndarray:
        """Each edge's length in the space: the roadmap's edges' computed once per set of moving coordinates (and shared
        by the copies: every transit query searches with them), the added ones' at each call."""
        key = space.idx.tobytes()
        if key not in self._roadmap_weights:
            self._roadmap_weights[key] = frozen(self._lengths(space, self.edges[: self.n_roadmap_edges]))
        return np.concatenate([self._roadmap_weights[key], self._lengths(space, self.edges[self.n_roadmap_edges:])])

    def _lengths(self, space: JointSpace, edges: np.ndarray) -> np.ndarray:
        return space.distance(self.q[edges[:, 0]], self.q[edges[:, 1]])

    def copy(self) -> "MotionGraph":
        """An independent copy, cheap: the arrays are only ever replaced (never written in place), so they are shared;
        the edge index is a new dict of the same immutable keys."""
        out = copy.copy(self)
        out.index = dict(self.index)
        return out

    def add_nodes(self, q: np.ndarray) -> np.ndarray:
        q = np.atleast_2d(q)
        self.q = np.concatenate([self.q, q])
        return np.arange(len(self.q) - len(q), len(self.q))

    def add_edges(self, pairs: list[tuple[int, int]]) -> None:
        """Edges that no offline check covers (connections, reconnections); pairs already joined are skipped."""
        new = list(dict.fromkeys(_key(u, v) for u, v in pairs if u != v and _key(u, v) not in self.index))
        start = len(self.edges)
        for k, (u, v) in enumerate(new):
            self.index[_key(u, v)] = start + k
        self.edges = np.concatenate([self.edges, np.array(new, dtype=np.int64).reshape(-1, 2)])
        self.offline = np.concatenate([self.offline, np.zeros(len(new), dtype=bool)])

    def edge_id(self, u: int, v: int) -> int:
        return self.index[_key(u, v)]


class PhaseStatus:
    """One phase's knowledge of the graph: node and edge status (unknown / valid / invalid)."""

    def __init__(self, graph: MotionGraph):
        self.graph = graph
        self.node = np.zeros(len(graph.q), dtype=np.int8)
        self.edge = np.zeros(len(graph.edges), dtype=np.int8)

    def grow(self) -> None:
        """Extend the status arrays to nodes and edges added since (as unknown)."""
        g = self.graph
        self.node = np.concatenate([self.node, np.zeros(len(g.q) - len(self.node), np.int8)])[: len(g.q)]
        self.edge = np.concatenate([self.edge, np.zeros(len(g.edges) - len(self.edge), np.int8)])[: len(g.edges)]

    def usable(self) -> np.ndarray:
        """Edges a search may use: not invalid, and neither end invalid."""
        e = self.graph.edges
        return (self.edge != INVALID) & (self.node[e[:, 0]] != INVALID) & (self.node[e[:, 1]] != INVALID)

    def shortest_path(self, weights: np.ndarray, source: int, target: int) -> list[int] | None:
        """Node ids of a shortest path over the usable edges (weights per edge), or None."""
        use = self.usable()
        return shortest_path(len(self.graph.q), self.graph.edges[use], weights[use], source, target)

    def components(self) -> np.ndarray:
        """Connected-component label of every node over the usable edges."""
        e = self.graph.edges[self.usable()]
        n = len(self.graph.q)
        m = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
        return connected_components(m, directed=False)[1]


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


def _key(u: int, v: int) -> tuple[int, int]:
    return (int(u), int(v)) if u < v else (int(v), int(u))
