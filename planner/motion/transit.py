"""Transit motions (paper V-B): the Super Graph query with lazy revalidation, RRT reconnection, then shortcutting.

The query connects the start and the goal to their nearest graph nodes and searches the graph
disregarding the phase (Dijkstra over edges not known invalid). The path found is then validated
in the phase: roadmap nodes and edges only over the pairs the offline roadmap did not check
('changed': the object, a hand holding it), edges nobody checked offline (connections, earlier
reconnections) over every pair. Invalid edges are marked and the search runs again. When the
graph cannot join the two ends any more, the collision-free configurations bounding the invalid
portion of the last path (or, when no path was ever found, the closest valid nodes of the start's
and the goal's components) are reconnected with OMPL's RRTConnect, and its path is added to the
graph, as the paper enriches its PRM with RRT trees. The single-query baseline (`rrt_transit`) runs
RRTConnect alone between the same ends.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .graph import INVALID, VALID, MotionGraph, PhaseStatus
from .rrt import rrt_connect
from .space import JointSpace
from .validity import MotionValidity


@dataclass(frozen=True)
class TransitParams:
    connections: int = 8  # graph nodes each end is joined to (nearest first) ...
    max_connections: int = 48  # ... and more, a batch at a time, while all its edges are invalid
    max_searches: int = 60  # searches after invalidations before giving up
    max_reconnections: int = 4  # RRTConnect calls per transit
    reconnect_time: float = 5.0  # s per RRTConnect reconnection
    rrt_time: float = 30.0  # s per RRTConnect query of the baseline
    rrt_step: float = 0.5  # rad: RRTConnect's range (longest extension)
    shortcut_attempts: int = 24


@dataclass
class TransitStats:
    """Table I's figures for transit motions (summed over a phase's transits)."""

    nodes_planning: int = 0  # nodes added to connect queries
    nodes_validating: int = 0  # nodes added by RRT reconnection while validating
    seconds_planning: float = 0.0  # connecting and searching
    seconds_validating: float = 0.0  # lazy validation and reconnection
    seconds_shortcut: float = 0.0
    seconds_contact: float = 0.0  # straight hand motions and finger motions: IK and checks
    edges_invalidated: int = 0
    rrt_calls: int = 0
    searches: int = 0


class TransitFailed(Exception):
    """No transit path: `part` names what failed (for the step's failure message)."""


def _rrt(space: JointSpace, full: MotionValidity, qa: np.ndarray, qb: np.ndarray, seed: int, time_limit: float,
         step: float) -> np.ndarray | None:
    """RRTConnect between two full configurations of the space with full validity, extending by at most `step` (joint-space
    distance; short steps keep each motion check cheap); the path as full configurations."""
    result = rrt_connect(space.lower, space.upper, lambda x: full.state_valid(space.full(x)),
                         lambda a, b: full.motion_valid(space.full(a), space.full(b), ends=False),
                         space.reduce(qa), space.reduce(qb), seed=seed, time_limit=time_limit, range_=step)
    return space.full(result.path) if result.found else None


class LazyTransit:
    """Transit queries of one phase on the shared graph: `lazy` checks roadmap elements, `full` everything else, and
    `near` (denser: paddings fitted to the query's ends) whatever touches the start or the goal."""

    def __init__(self, graph: MotionGraph, space: JointSpace, lazy: MotionValidity, full: MotionValidity, near: MotionValidity,
                 params: TransitParams, rng: np.random.Generator, stats: TransitStats):
        self.graph, self.space, self.lazy, self.full, self.near, self.p, self.rng, self.stats = \
            graph, space, lazy, full, near, params, rng, stats
        self.ends: tuple[int, ...] = ()
        self.status = PhaseStatus(graph)
        self.joined: dict[int, int] = {}  # query end -> how many nearest nodes it was joined to

    def _config(self, node: int) -> np.ndarray:
        """A graph node as a configuration of this phase (its hands as the phase holds them)."""
        return self.space.full(self.space.reduce(self.graph.q[node]))

    def _weights(self) -> np.ndarray:
        e = self.graph.edges
        return self.space.distance(self.graph.q[e[:, 0]], self.graph.q[e[:, 1]])

    def _connect(self, q: np.ndarray) -> int:
        """Add q as a node joined (unchecked) to its nearest nodes; returns its id."""
        node = int(self.graph.add_nodes(q)[0])
        self.joined[node] = 0
        self._join(node)
        self.stats.nodes_planning += 1
        return node

    def _join(self, node: int) -> None:
        """Join a query end (unchecked) to its next `connections` nearest nodes."""
        d = self.space.distance(self.graph.q, self.graph.q[node])
        d[node] = np.inf
        order = np.argsort(d, kind="stable")
        k = self.joined[node]
        self.graph.add_edges([(node, int(n)) for n in order[k: k + self.p.connections]])
        self.joined[node] = k + self.p.connections
        self.status.grow()

    def _widen(self, node: int) -> bool:
        """When every edge of a query end is known invalid, join it to its next nearest nodes (up to
        `max_connections`); True if it was widened."""
        g = self.graph
        mine = (g.edges[:, 0] == node) | (g.edges[:, 1] == node)
        if np.any(self.status.usable() & mine) or self.joined[node] >= self.p.max_connections:
            return False
        self._join(node)
        return True

    def _node_valid(self, n: int) -> bool:
        st = self.status
        if st.node[n] == 0:
            check = self.lazy if n < self.graph.n_roadmap else self.near if n in self.ends else self.full
            st.node[n] = VALID if check.state_valid(self._config(n)) else INVALID
        return st.node[n] == VALID

    def _edge_valid(self, u: int, v: int) -> bool:
        st, g = self.status, self.graph
        k = g.edge_id(u, v)
        if st.edge[k] == 0:
            check = self.lazy if g.offline[k] else self.near if u in self.ends or v in self.ends else self.full
            ok = check.motion_valid(self._config(u), self._config(v), ends=False)
            st.edge[k] = VALID if ok else INVALID
            self.stats.edges_invalidated += int(not ok)
        return st.edge[k] == VALID

    def _validate(self, path: list[int]) -> list[bool]:
        """Per edge of the path: valid (its ends and itself); every element of the path is checked (cached)."""
        nodes_ok = [self._node_valid(n) for n in path]
        return [nodes_ok[i] and nodes_ok[i + 1] and self._edge_valid(path[i], path[i + 1]) for i in range(len(path) - 1)]

    def _bounds(self, path: list[int] | None, start: int, goal: int) -> tuple[int, int]:
        """The valid nodes to reconnect: around the invalid portion of the last path, else the closest valid pair
        of the start's and the goal's components."""
        if path is not None:
            ok = self._validate(path)
            first, last = ok.index(False), len(ok) - 1 - ok[::-1].index(False)
            return path[first], path[last + 1]
        comp = self.status.components()
        a_ids, b_ids = np.flatnonzero(comp == comp[start]), np.flatnonzero(comp == comp[goal])
        d = np.linalg.norm(self.space.reduce(self.graph.q[a_ids])[:, None] - self.space.reduce(self.graph.q[b_ids])[None], axis=2)
        for flat in np.argsort(d, axis=None, kind="stable")[:50]:
            a, b = int(a_ids[flat // len(b_ids)]), int(b_ids[flat % len(b_ids)])
            if self._node_valid(a) and self._node_valid(b):
                return a, b
        return start, goal

    def query(self, q_start: np.ndarray, q_goal: np.ndarray) -> np.ndarray:
        """A valid polyline (full configurations) from q_start to q_goal; both ends must be valid states."""
        stats = self.stats
        t0 = time.perf_counter()
        if self.near.motion_valid(q_start, q_goal, ends=False):
            stats.seconds_planning += time.perf_counter() - t0
            return np.stack([q_start, q_goal])
        start, goal = self._connect(q_start), self._connect(q_goal)
        self.ends = (start, goal)
        self.status.grow()
        self.status.node[[start, goal]] = VALID
        stats.seconds_planning += time.perf_counter() - t0
        last: list[int] | None = None
        weights = self._weights()
        for _ in range(self.p.max_searches + self.p.max_reconnections):
            t = time.perf_counter()
            path = self.status.shortest_path(weights, start, goal)
            stats.searches += 1
            stats.seconds_planning += time.perf_counter() - t
            t = time.perf_counter()
            if path is not None:
                ok = self._validate(path)
                stats.seconds_validating += time.perf_counter() - t
                if all(ok):
                    return np.array([self._config(n) for n in path])
                last = path
                if stats.searches < self.p.max_searches:
                    continue
            if stats.rrt_calls >= self.p.max_reconnections:
                break
            if self._widen(start) | self._widen(goal):
                weights = self._weights()
                stats.seconds_validating += time.perf_counter() - t
                continue
            a, b = self._bounds(last, start, goal)
            stats.rrt_calls += 1
            check = self.near if a in self.ends or b in self.ends else self.full
            found = _rrt(self.space, check, self._config(a), self._config(b), int(self.rng.integers(2**31)), self.p.reconnect_time,
                         self.p.rrt_step)
            if found is not None:
                ids = self.graph.add_nodes(found[1:-1])
                chain = [a, *ids.tolist(), b]
                self.graph.add_edges(list(zip(chain[:-1], chain[1:])))
                self.status.grow()
                self.status.node[ids] = VALID
                for u, v in zip(chain[:-1], chain[1:]):
                    self.status.edge[self.graph.edge_id(u, v)] = VALID
                stats.nodes_validating += len(ids)
                weights = self._weights()
            last = None
            stats.seconds_validating += time.perf_counter() - t
        raise TransitFailed(f"no path: {stats.searches} searches, {stats.edges_invalidated} edges invalidated, "
                            f"{stats.rrt_calls} RRT reconnections")


def rrt_transit(space: JointSpace, full: MotionValidity, q_start: np.ndarray, q_goal: np.ndarray, params: TransitParams,
                rng: np.random.Generator, stats: TransitStats) -> np.ndarray:
    """The single-query baseline: RRTConnect between the ends, every pair checked."""
    t = time.perf_counter()
    stats.rrt_calls += 1
    found = _rrt(space, full, q_start, q_goal, int(rng.integers(2**31)), params.rrt_time, params.rrt_step)
    stats.seconds_planning += time.perf_counter() - t
    if found is None:
        raise TransitFailed(f"RRTConnect found no path within {params.rrt_time:g} s")
    stats.nodes_planning += len(found) - 2
    return found


def shortcut(path: np.ndarray, full: MotionValidity, near: MotionValidity, rng: np.random.Generator, attempts: int) -> np.ndarray:
    """Random shortcuts between two points of the polyline (by arc length), kept when the straight motion is valid
    (checked with `near` when it leaves the first segment or reaches the last: close to the ends)."""
    path = np.array(path, dtype=float)
    for _ in range(attempts):
        if len(path) < 3:
            break
        seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        s1, s2 = np.sort(rng.uniform(0.0, cum[-1], 2))
        i, j = (min(int(np.searchsorted(cum, s, side="right")) - 1, len(seg) - 1) for s in (s1, s2))
        if i == j:
            continue
        a = path[i] + (s1 - cum[i]) / max(seg[i], 1e-12) * (path[i + 1] - path[i])
        b = path[j] + (s2 - cum[j]) / max(seg[j], 1e-12) * (path[j + 1] - path[j])
        if (near if i == 0 or j == len(seg) - 1 else full).motion_valid(a, b, ends=False):
            path = np.concatenate([path[: i + 1], [a, b], path[j + 1:]])
    return _drop_duplicates(path)


def _drop_duplicates(path: np.ndarray) -> np.ndarray:
    keep = np.concatenate([[True], np.linalg.norm(np.diff(path, axis=0), axis=1) > 1e-9])
    return path[keep]
