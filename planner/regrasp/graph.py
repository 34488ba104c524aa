"""The regrasp graph: which hand holds the object in which grasp where, and the transitions between, searched for the
sequences from the initial placement to the final one, cheapest first.

A node is (the hand holding the object, its grasp, the placement where the object is): at the initial placement
just picked, at the final one about to be placed, or at an intermediate placement (the placements step's) just set
down or just taken. Edges are the transitions a hand makes: pick the object from a placement, carry it to another
and set it down there, let go and take it there (the other hand, or the same hand in another grasp), hand it over
in the air (a double grasp), place it. Each has the robot's configuration where it ends, so its cost, a motion-time
estimate, is the joint-space distance travelled over the joint speed limit plus a fixed time per contact motion
(approach, closing, lift, set-down, opening, retreat), which the straight distance cannot see.

The search is A* over sequences (the graph is searched as the tree of its paths: a node reached by two routes is two
sequences to the motion, which may make one and not the other), its estimate of what is left a lower bound: the
contact motions still to make and the straight joint distance to the final configuration. Configurations at
intermediate placements cost an IK search each, so an edge may be lazy: queued at a lower bound (its contact time)
and only made when it is popped; one that cannot be made is counted with its reason. Sequences come out cheapest
first.
"""
from __future__ import annotations

import heapq
import itertools
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import numpy as np

INITIAL, FINAL = -1, -2  # `at` of the task's placements; intermediate ones are indices into the placements step's list
HANDOVER, TABLE, REGRASP = "handover", "table", "regrasp"  # a sequence's strategy (see Sequence.strategy)


@dataclass(frozen=True)
class Node:
    """The object held by `hand` in grasp `grasp` of its `grasps` list ('pick' or 'place') at placement `at`; the
    object at rest with no hand on it: hand ''."""

    hand: str
    grasps: str
    grasp: int
    at: int

    def describe(self) -> str:
        where = {INITIAL: "the initial placement", FINAL: "the final placement"}.get(self.at, f"placement {self.at + 1}")
        return f"at {where}" if not self.hand else f"{self.hand} hand, {self.grasps} grasp {self.grasp + 1}, at {where}"


START, GOAL = Node("", "", -1, INITIAL), Node("", "", -1, FINAL)


@dataclass(frozen=True)
class Edge:
    """A transition out of a node: its kind, where it leads, how many contact motions it makes, and either its
    configurations (the waypoints the robot passes, the last where it ends) or `make`, which computes them (None:
    it cannot be made, `why` says why); `rank` is the double grasp's rank for a handover (-1 otherwise)."""

    kind: str
    target: Node
    contacts: int
    waypoints: np.ndarray | None = None
    make: Callable[[], np.ndarray | None] | None = None
    why: str = ""
    rank: int = -1


@dataclass(frozen=True)
class Transition:
    """A made edge: its kind, where it leads, where the robot ends (q), its estimated seconds, the double grasp's rank."""

    kind: str
    target: Node
    q: np.ndarray
    seconds: float
    rank: int = -1


@dataclass(frozen=True)
class Sequence:
    """Transitions from the initial placement to the final one, and their estimated seconds."""

    transitions: tuple[Transition, ...]
    seconds: float

    @property
    def strategy(self) -> str:
        """'table' when the object changes hands at an intermediate placement, 'regrasp' when the same hand takes it
        again there, else 'handover' (in the air, or a direct transfer by the one arm)."""
        for t, u in zip(self.transitions, self.transitions[1:]):
            if u.kind == "take":
                return TABLE if u.target.hand != t.target.hand else REGRASP
        return HANDOVER

    @classmethod
    def of(cls, costs: CostModel, q_start: np.ndarray, edges: list[Edge]) -> Sequence:
        """The sequence of made edges (each with its configurations) from q_start."""
        out, q = [], q_start
        for e in edges:
            out.append(Transition(e.kind, e.target, e.waypoints[-1], costs.seconds(q, e.waypoints, e.contacts), e.rank))
            q = out[-1].q
        return cls(tuple(out), sum(t.seconds for t in out))

    def describe(self) -> list[dict]:
        """The transitions as the motion result stores them."""
        return [{"kind": t.kind, "hand": t.target.hand, "grasps": t.target.grasps, "grasp": t.target.grasp, "at": t.target.at,
                 "seconds": round(t.seconds, 3), **({"double_grasp": t.rank} if t.rank >= 0 else {})} for t in self.transitions]


@dataclass(frozen=True)
class CostModel:
    """The motion-time estimate of a transition: joint-space distance over the joint speed, plus a fixed time per
    contact motion."""

    velocity: float  # rad/s
    contact: float  # s per contact motion

    def seconds(self, q: np.ndarray, waypoints: np.ndarray, contacts: int) -> float:
        path = np.vstack([q[None], waypoints])
        return float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum()) / self.velocity + contacts * self.contact


Expand = Callable[[Node, tuple[Transition, ...]], list[Edge]]


@dataclass
class Search:
    """The search from START to GOAL (see the module), A* with an admissible estimate of what is left: the contact
    motions still to make at least (`remaining`) and the straight joint distance to the goal's configuration. `dropped`
    counts the lazy edges that could not be made, by reason; `expanded` the nodes whose edges were listed."""

    costs: CostModel
    expand: Expand
    q_start: np.ndarray
    q_goal: np.ndarray
    remaining: Callable[[Node], int]
    dropped: Counter = field(default_factory=Counter)
    expanded: int = 0

    def __post_init__(self) -> None:
        self._order = itertools.count()
        self._heap: list = []
        self._push(0.0, (), None, START, self.q_start)

    def _push(self, cost: float, path: tuple[Transition, ...], pending: Edge | None, node: Node, q: np.ndarray) -> None:
        """Queue a path (and a lazy edge out of its end, to be made when popped, leading to `node`) at its cost plus the
        estimate of what is left after it: the contact motions (the lazy edge's too) and the straight distance from q
        (where the path ends: through the lazy edge's unmade configuration, the way to the goal is no shorter)."""
        left = (self.remaining(node) + (pending.contacts if pending is not None else 0)) * self.costs.contact
        left += float(np.linalg.norm(self.q_goal - q)) / self.costs.velocity
        heapq.heappush(self._heap, (cost + left, next(self._order), cost, path, pending))

    def next_below(self, bound: float = np.inf) -> Sequence | None:
        """The next cheapest sequence if it costs at most `bound` (None: none left, or the next costs more; what is
        queued stays queued for a later call)."""
        while self._heap and self._heap[0][0] <= bound:
            _, _, cost, path, pending = heapq.heappop(self._heap)
            node, q = (path[-1].target, path[-1].q) if path else (START, self.q_start)
            if pending is not None:  # a lazy edge: make it now, queue it at its real cost
                waypoints = pending.make()
                if waypoints is None:
                    self.dropped[pending.why] += 1
                    continue
                t = Transition(pending.kind, pending.target, waypoints[-1], self.costs.seconds(q, waypoints, pending.contacts))
                self._push(cost + t.seconds, path + (t,), None, t.target, t.q)
                continue
            if node == GOAL:
                return Sequence(path, cost)
            self.expanded += 1
            for e in self.expand(node, path):
                if e.make is not None:
                    self._push(cost, path, e, e.target, q)
                else:
                    t = Transition(e.kind, e.target, e.waypoints[-1], self.costs.seconds(q, e.waypoints, e.contacts), e.rank)
                    self._push(cost + t.seconds, path + (t,), None, t.target, t.q)
        return None

    def sequences(self) -> Iterator[Sequence]:
        """Every sequence, cheapest first (made lazily: stop iterating and nothing more is computed)."""
        while (seq := self.next_below()) is not None:
            yield seq
