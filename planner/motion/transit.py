"""Transit motions (paper V-B): the Super Graph query with lazy revalidation, RRT reconnection, then shortcutting.

The query joins the start and the goal to their nearest valid graph nodes within `max_join` (the first
edge of each checked: the ends are where a phase differs most from the roadmap; an end no edge joins is
reconnected to the other at once) and searches the graph disregarding the phase (Dijkstra over edges not known
invalid). The path found is then validated in the phase from both ends inward,
each side stopping at its first invalid edge: roadmap nodes and edges only over the pairs the
offline roadmap did not check ('changed': the object, a hand holding it), edges nobody checked
offline (connections, earlier reconnections) over every pair. Invalid elements are marked and the
search runs again. When the searches are used up, OMPL's RRTConnect reconnects the valid node before
the invalid span of the last path to the nodes after it (the goal tree grows from each, the goal
included); when the graph cannot join the ends at all, the end whose component is smaller is
reconnected to the other end and the nearest valid nodes of its component (the goal tree grows from
each: where the ends are nearer each other than the graph, it joins them directly). What RRTConnect
finds is added to the graph, as the paper enriches its PRM with RRT trees. The single-query
baseline (`rrt_transit`) runs RRTConnect alone between the ends.
"""
from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from planner.collision.validity import MotionValidity
from planner.motion.graph import INVALID, VALID, MotionGraph, PhaseStatus
from planner.motion.rrt import rrt_connect
from planner.motion.space import JointSpace


@dataclass(frozen=True)
class TransitParams:
    """The transit planners' share of the motion step's parameters (see MotionParams for what each means)."""

    connections: int
    max_connections: int
    max_join: float
    max_searches: int
    max_reconnections: int
    reconnect_motions: int
    away_motions: int
    rrt_motions: int
    rrt_step: float
    shortcut_attempts: int
    shortcut_min_gain: float
    graph_shortcut_length: float
    goal_nodes: int

    @classmethod
    def of(cls, params) -> "TransitParams":
        """The fields of the same names of a MotionParams."""
        return cls(**{f.name: getattr(params, f.name) for f in dataclasses.fields(cls)})


@dataclass
class TransitStats:
    """Table I's figures for transit motions (summed over a phase's transits)."""

    nodes_planning: int = 0  # nodes added to connect queries
    nodes_validating: int = 0  # nodes added by RRT reconnection while validating
    seconds_planning: float = 0.0  # connecting and searching
    seconds_validating: float = 0.0  # lazy validation
    seconds_reconnecting: float = 0.0  # RRTConnect (reconnections; the baseline's queries count as planning)
    seconds_shortcut: float = 0.0
    seconds_contact: float = 0.0  # straight hand motions and finger motions (IK and checks), their ends' clearances
    edges_invalidated: int = 0
    rrt_calls: int = 0
    searches: int = 0
    checks: int = 0  # collision checks of the transits (their ends, connecting, validating, reconnecting, shortcutting)
    pair_tests: int = 0  # of those checks' pairs, how many reached the exact test (a count of narrow-phase work)
    pairs_rrt: int = 0  # of those, the RRTConnect queries' (the baseline's) and reconnections' (ours')
    pairs_shortcut: int = 0  # and the shortcuts';
    pairs_away: int = 0  # and an arm's moved alone, whole (no graph answers them: RRTConnect and shortcuts for either
    # planner); the rest went to the ends, joining them to the graph and validating it
    ends_alone: int = 0  # query ends no edge joined to the graph (their query is RRTConnect's from there: see query)

    @property
    def transit_seconds(self) -> float:
        """The seconds in the transits themselves: searching, validating, reconnecting, shortcutting (not contact)."""
        return self.seconds_planning + self.seconds_validating + self.seconds_reconnecting + self.seconds_shortcut


class TransitFailed(Exception):
    """No transit path: `part` names what failed (for the step's failure message)."""


def _rrt(space: JointSpace, full: MotionValidity, qa: np.ndarray, qb: np.ndarray, seed: int, max_motions: int,
         step: float) -> np.ndarray | None:
    """RRTConnect from a full configuration of the space to another (or to any row of qb) with the given validity,
    extending by at most `step` (joint-space distance; short steps keep each motion check cheap); the path as full
    configurations."""
    goals = space.reduce(np.atleast_2d(qb))
    result = rrt_connect(space.lower, space.upper, lambda x: full.state_valid(space.full(x)),
                         lambda a, b: full.motion_valid(space.full(a), space.full(b), ends=False),
                         space.reduce(qa), goals[0], seed=seed, range_=step, more_goals=goals[1:], max_motions=max_motions)
    return space.full(result.path) if result.found else None


class LazyTransit:
    """Transit queries of one phase on the shared graph: `lazy` checks roadmap elements, `full` everything else, and
    `near` (denser: paddings fitted to the query's ends) whatever touches the start or the goal."""

    def __init__(self, graph: MotionGraph, space: JointSpace, lazy: MotionValidity, full: MotionValidity, near: MotionValidity,
                 params: TransitParams, rng: np.random.Generator, stats: TransitStats, pairs: Callable[[], int] = lambda: 0):
        self.graph, self.space, self.lazy, self.full, self.near, self.p, self.rng, self.stats = \
            graph, space, lazy, full, near, params, rng, stats
        self.pairs = pairs  # the pair tests made so far by the checkers of these validities (for stats.pairs_rrt)
        self.ends: tuple[int, ...] = ()
        self.alone: set[int] = set()  # the ends no graph node joins
        self.status = PhaseStatus(graph)
        self.reconnected: set[int] = set()  # the edges RRTConnect made
        self.detours = np.zeros(0, dtype=bool)  # per segment of the path `query` returned: one of those edges

    def _config(self, node: int) -> np.ndarray:
        """A graph node as a configuration of this phase (its hands as the phase holds them)."""
        return self.space.full(self.space.reduce(self.graph.q[node]))

    def _weights(self) -> np.ndarray:
        return self.graph.weights(self.space)

    def _connect(self, node: int) -> int:
        """Join a query end to its nearest valid graph nodes, nearest first: by checked edges until one is valid (an end
        no edge joins, among `max_connections` nodes no farther than `max_join`, is where a phase differs most from the
        roadmap: it is reconnected at once), then by `connections` - 1 more edges unchecked, validated if a path takes
        them (an edge from an end is long: the search takes one of them); how many joined."""
        g, st = self.graph, self.status
        d = self.space.distance(g.q[: g.n_roadmap], g.q[node])
        joined = 0
        for n in np.argsort(d, kind="stable")[: self.p.max_connections]:
            if joined >= self.p.connections or d[n] > self.p.max_join:
                break
            if self._node_valid(int(n)):
                g.add_edges([(node, int(n))])
                st.grow()
                joined += 1 if joined else self._edge_valid(node, int(n))
        return joined

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

    def _invalid_span(self, path: list[int]) -> tuple[int, int] | None:
        """(first, last) invalid edge of the path (an edge is invalid with either end), checked from both ends inward,
        where a phase differs most from the roadmap, each side stopping at its first invalid edge; None if all valid."""
        def edge_ok(i: int) -> bool:
            return self._node_valid(path[i]) and self._node_valid(path[i + 1]) and self._edge_valid(path[i], path[i + 1])

        front, back = 0, len(path) - 2
        first = last = None
        while front <= back and (first is None or last is None):
            if first is None:
                if edge_ok(front):
                    front += 1
                else:
                    first = front
            if last is None and front <= back:
                if edge_ok(back):
                    back -= 1
                else:
                    last = back
        return None if first is None else (first, first if last is None else last)

    def _reconnection(self, last: tuple[list[int], tuple[int, int]] | None, start: int, goal: int) -> tuple[int, list[int]]:
        """The valid node a reconnection starts from and the valid nodes it may end at: across the invalid span of the
        last path, to the first valid node after it or any later one of the path, the goal included (a span that no
        detour crosses near its end is crossed further along, or straight to the goal, as RRTConnect alone would); else
        (the ends' components apart) from the end whose component is smaller to the other end and the valid nodes of its
        component nearest it, so the tree joins the other end or the graph wherever it reaches first."""
        if last is not None:
            path, (first, final) = last
            return path[first], list(path[final + 1:])
        comp = self.status.components()
        size = np.bincount(comp)
        root, other = (start, goal) if size[comp[start]] <= size[comp[goal]] else (goal, start)
        ids = np.flatnonzero((comp == comp[other]) & (self.status.node != INVALID))
        ids = ids[ids != other]
        goals: list[int] = []
        for n in ids[np.argsort(self.space.distance(self.graph.q[ids], self.graph.q[root]), kind="stable")][: 3 * self.p.goal_nodes]:
            if len(goals) == self.p.goal_nodes:
                break
            if self._node_valid(int(n)):
                goals.append(int(n))
        return root, [other] + goals

    def query(self, q_start: np.ndarray, q_goal: np.ndarray) -> np.ndarray:
        """A valid polyline (full configurations) from q_start to q_goal; both ends must be valid states."""
        stats = self.stats
        t0 = time.perf_counter()
        if self.near.motion_valid(q_start, q_goal, ends=False):
            stats.seconds_planning += time.perf_counter() - t0
            self.detours = np.zeros(1, dtype=bool)
            return np.stack([q_start, q_goal])
        start, goal = (int(n) for n in self.graph.add_nodes(np.stack([q_start, q_goal])))
        self.ends = (start, goal)
        self.status.grow()
        self.status.node[[start, goal]] = VALID
        if self._connect(start):  # else the graph cannot help: the start is reconnected to the goal directly
            self.alone = set() if self._connect(goal) else {goal}
        else:
            self.alone = {start, goal}
        stats.ends_alone += len(self.alone)
        stats.nodes_planning += 2
        stats.seconds_planning += time.perf_counter() - t0
        last: tuple[list[int], tuple[int, int]] | None = None
        weights = self._weights()
        searches = reconnections = 0  # this query's (stats sum a phase's queries)
        invalidated = stats.edges_invalidated
        for _ in range(self.p.max_searches + self.p.max_reconnections):
            t = time.perf_counter()
            path = self.status.shortest_path(weights, start, goal)
            stats.searches += 1
            searches += 1
            stats.seconds_planning += time.perf_counter() - t
            t = time.perf_counter()
            if path is not None:
                span = self._invalid_span(path)
                stats.seconds_validating += time.perf_counter() - t
                if span is None:
                    made = [self.graph.edge_id(u, v) in self.reconnected for u, v in zip(path[:-1], path[1:])]
                    self.detours = np.array(made, dtype=bool)
                    return np.array([self._config(n) for n in path])
                last = (path, span)
                if searches < self.p.max_searches:
                    continue
            if reconnections >= self.p.max_reconnections:
                break
            a, targets = self._reconnection(last, start, goal)
            stats.rrt_calls += 1
            reconnections += 1
            check = self.near if {a, *targets} & set(self.ends) else self.full
            single = a in self.alone  # the graph joins not this end: the query is the baseline's, and so is its budget
            t_rrt, pairs_before = time.perf_counter(), self.pairs()
            found = _rrt(self.space, check, self._config(a), np.array([self._config(n) for n in targets]),
                         int(self.rng.integers(2**31)), self.p.rrt_motions if single else self.p.reconnect_motions,
                         self.p.rrt_step)
            stats.seconds_reconnecting += time.perf_counter() - t_rrt
            stats.pairs_rrt += self.pairs() - pairs_before
            t += time.perf_counter() - t_rrt  # the RRT's time is not validation's
            if found is None and single:
                break
            if found is not None:
                ids = self.graph.add_nodes(found[1:-1])
                reached = self.space.distance(np.array([self._config(n) for n in targets]), found[-1])
                chain = [a, *ids.tolist(), targets[int(np.argmin(reached))]]
                self.graph.add_edges(list(zip(chain[:-1], chain[1:])))
                self.status.grow()
                self.status.node[ids] = VALID
                for u, v in zip(chain[:-1], chain[1:]):
                    self.status.edge[self.graph.edge_id(u, v)] = VALID
                    self.reconnected.add(self.graph.edge_id(u, v))
                stats.nodes_validating += len(ids)
                weights = self._weights()
            last = None
            stats.seconds_validating += time.perf_counter() - t
        raise TransitFailed(f"no path: {searches} searches, {stats.edges_invalidated - invalidated} edges invalidated, "
                            f"{reconnections} RRT reconnections")


def rrt_transit(space: JointSpace, full: MotionValidity, near: MotionValidity, q_start: np.ndarray, q_goal: np.ndarray,
                params: TransitParams, rng: np.random.Generator, stats: TransitStats) -> np.ndarray:
    """The single-query baseline: RRTConnect between the ends, every pair checked, as densely as the ends need (a single
    query cannot tell their neighbourhood from the rest)."""
    t = time.perf_counter()
    stats.rrt_calls += 1
    found = _rrt(space, near, q_start, q_goal, int(rng.integers(2**31)), params.rrt_motions, params.rrt_step)
    stats.seconds_planning += time.perf_counter() - t
    if found is None:
        raise TransitFailed(f"RRTConnect found no path within {params.rrt_motions} motion checks")
    stats.nodes_planning += len(found) - 2
    return found


def shortcut_vertices(path: np.ndarray, full: MotionValidity, near: MotionValidity, min_gain: float = 0.0,
                      max_length: float = np.inf, detours: np.ndarray | None = None) -> np.ndarray:
    """Greedy shortcuts between vertices: from the first vertex, a straight motion to the farthest later vertex it can
    reach validly (checked with `near` from the first or to the last vertex: close to the ends), then on from there. Each
    motion kept is checked once (random shortcuts check many that a later one replaces) and the path keeps few vertices,
    each a stop of the rest-to-rest timing. A jump that would shorten the path by less than `min_gain` is taken along the
    path itself, unchecked (the gain only grows with the vertex jumped to: no nearer one gains more); one longer than
    `max_length` is not tried unless it replaces a detour RRTConnect made (`detours`, a flag per segment; None: none): a
    path of roadmap edges, checked offline, keeps them rather than pay every pair's checks along a long new motion, but
    a reconnection's detour, checked over every pair as the jump would be, is cut however long."""
    path = np.asarray(path, dtype=float)
    n = len(path)
    flags = np.zeros(n - 1, dtype=bool) if detours is None else np.asarray(detours, dtype=bool)
    cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))])
    out, i = [path[0]], 0
    while i < n - 1:
        j = n - 1
        while j > i + 1:
            straight = float(np.linalg.norm(path[j] - path[i]))
            if cum[j] - cum[i] - straight < min_gain:
                out.extend(path[i + 1: j])  # nearly straight already
                break
            if ((straight <= max_length or flags[i:j].any())
                    and (near if i == 0 or j == n - 1 else full).motion_valid(path[i], path[j])):
                break
            j -= 1
        out.append(path[j])
        i = j
    return _drop_duplicates(np.array(out))


def shortcut(path: np.ndarray, full: MotionValidity, near: MotionValidity, rng: np.random.Generator, attempts: int,
             min_gain: float = 0.0, max_length: float = np.inf, detours: np.ndarray | None = None) -> np.ndarray:
    """Random shortcuts between two points of the polyline (by arc length), kept when the two points and the straight
    motion between them are valid (checked with `near` when it leaves the first segment or reaches the last: close to
    the ends). The points are checked too: one inside a checked segment keeps the clearance, not the padding that a
    motion check needs at both ends for its guarantee. A shortcut that would shorten the path by less than `min_gain`
    (joint-space length) is not checked: a valid one costs every check of its segment, and once the path is nearly
    straight most would gain nothing. One longer than `max_length` is not checked either, unless it replaces part of a
    detour (`detours`: see shortcut_vertices)."""
    path = np.array(path, dtype=float)
    flags = np.zeros(max(len(path) - 1, 0), dtype=bool) if detours is None else np.asarray(detours, dtype=bool)
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
        if s2 - s1 - float(np.linalg.norm(b - a)) < min_gain or (float(np.linalg.norm(b - a)) > max_length and not flags[i: j + 1].any()):
            continue
        if (near if i == 0 or j == len(seg) - 1 else full).motion_valid(a, b):
            path = np.concatenate([path[: i + 1], [a, b], path[j + 1:]])
            flags = np.concatenate([flags[: i + 1], [False], flags[j:]])  # the pieces of segments i and j keep theirs
    return _drop_duplicates(path)


def kept_detours(path: np.ndarray, detours: np.ndarray, out: np.ndarray) -> np.ndarray:
    """Per segment of `out` (vertices of `path` after shortcut_vertices): whether it is one of `path`'s detour segments
    (`detours`, a flag per segment of `path`); a jump the shortcuts made is not."""
    edges = {(a.tobytes(), b.tobytes()) for a, b, f in zip(path[:-1], path[1:], detours) if f}
    return np.array([(a.tobytes(), b.tobytes()) in edges for a, b in zip(out[:-1], out[1:])], dtype=bool)


def _drop_duplicates(path: np.ndarray) -> np.ndarray:
    keep = np.concatenate([[True], np.linalg.norm(np.diff(path, axis=0), axis=1) > 1e-9])
    return path[keep]
