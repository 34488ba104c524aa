"""RRTConnect adapter: real OMPL solves on small boxes with walls, checked independently of the planner."""
from __future__ import annotations

import numpy as np
import pytest

from planner.motion.rrt import RRTResult, rrt_connect

STEP = 0.005  # the test's own motion-checking resolution
SQUARE_LOW, SQUARE_HIGH = np.zeros(2), np.ones(2)
WALL_X = (0.45, 0.55)  # a vertical wall across the unit square...
GAP_Y = (0.75, 0.85)  # ...open here, away from the straight line between START and GOAL
START, GOAL = np.array([0.1, 0.1]), np.array([0.9, 0.1])


def box_distance(points: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Euclidean distance from each point (n, d) to the axis-aligned box [lo, hi] (0 inside)."""
    return np.linalg.norm(np.maximum(0.0, np.maximum(lo - points, points - hi)), axis=-1)


def wall_boxes(gap: bool) -> list[tuple[np.ndarray, np.ndarray]]:
    """The wall as boxes: two pieces around the gap, or one closed piece."""
    if not gap:
        return [(np.array([WALL_X[0], 0.0]), np.array([WALL_X[1], 1.0]))]
    return [(np.array([WALL_X[0], 0.0]), np.array([WALL_X[1], GAP_Y[0]])),
            (np.array([WALL_X[0], GAP_Y[1]]), np.array([WALL_X[1], 1.0]))]


def clearance(points: np.ndarray, boxes: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
    """Distance from each point to the nearest box."""
    return np.min([box_distance(points, lo, hi) for lo, hi in boxes], axis=0)


def segment_points(a: np.ndarray, b: np.ndarray, step: float) -> np.ndarray:
    """Points from a to b (both included) no more than `step` apart."""
    n = max(1, int(np.ceil(np.linalg.norm(b - a) / step)))
    return a + np.linspace(0.0, 1.0, n + 1)[:, None] * (b - a)


def checkers(boxes: list[tuple[np.ndarray, np.ndarray]]):
    """state_valid: outside every box; motion_valid: points STEP apart all farther than STEP/2 from the boxes.

    Every point of a segment is within STEP/2 of a checked point, so an accepted segment is free
    of the boxes exactly, and a finer re-check can never disagree.
    """
    def state_valid(q: np.ndarray) -> bool:
        return bool(clearance(q[None], boxes)[0] > 0.0)

    def motion_valid(a: np.ndarray, b: np.ndarray) -> bool:
        return bool(np.all(clearance(segment_points(a, b, STEP), boxes) > STEP / 2))

    return state_valid, motion_valid


def assert_free_path(result: RRTResult, start: np.ndarray, goal: np.ndarray, boxes) -> None:
    """Found, from start to goal exactly, every segment free at 10x the checker's resolution."""
    assert result.found, result.message
    assert result.message == ""
    assert result.path.shape[1] == start.size and len(result.path) >= 2
    assert np.array_equal(result.path[0], start) and np.array_equal(result.path[-1], goal)
    for a, b in zip(result.path[:-1], result.path[1:]):
        assert np.all(clearance(segment_points(a, b, STEP / 10), boxes) > 0.0), (a, b)
    assert result.states >= len(result.path)


def test_wall_with_gap_is_crossed_through_the_gap():
    boxes = wall_boxes(gap=True)
    state_valid, motion_valid = checkers(boxes)
    result = rrt_connect(SQUARE_LOW, SQUARE_HIGH, state_valid, motion_valid, START, GOAL, seed=1, time_limit=10.0)
    assert_free_path(result, START, GOAL, boxes)
    assert result.seconds >= 0.0


def test_same_seed_same_path_and_the_seed_is_used():
    state_valid, motion_valid = checkers(wall_boxes(gap=True))

    def solve(seed: int) -> np.ndarray:
        result = rrt_connect(SQUARE_LOW, SQUARE_HIGH, state_valid, motion_valid, START, GOAL, seed=seed,
                             time_limit=10.0)
        assert result.found, result.message
        return result.path

    first, other, again = solve(7), solve(8), solve(7)  # another solve in between must not matter
    assert np.array_equal(first, again)
    assert not (first.shape == other.shape and np.array_equal(first, other))


def test_closed_wall_gives_no_path_with_a_message():
    state_valid, motion_valid = checkers(wall_boxes(gap=False))
    result = rrt_connect(SQUARE_LOW, SQUARE_HIGH, state_valid, motion_valid, START, GOAL, seed=3, time_limit=0.3)
    assert not result.found
    assert result.path.shape == (0, 2)
    assert "no path" in result.message and result.states > 2


def test_invalid_start_is_reported_without_planning():
    state_valid, motion_valid = checkers(wall_boxes(gap=True))
    result = rrt_connect(SQUARE_LOW, SQUARE_HIGH, state_valid, motion_valid, np.array([0.5, 0.1]), GOAL, seed=1)
    assert not result.found and result.message == "start invalid" and result.path.shape == (0, 2)


def test_motions_are_decided_by_motion_valid_not_by_states():
    """Every state is valid; only segments crossing the line x = 0.5 outside the gap are not.

    OMPL's own discrete checker would accept the straight segment START-GOAL (it crosses at y = 0.1).
    """
    def crossing_ys(a: np.ndarray, b: np.ndarray) -> list[float]:
        """The heights at which the segment a-b meets the line x = 0.5 (its ends if it lies on the line)."""
        if (a[0] - 0.5) * (b[0] - 0.5) > 0:
            return []
        if a[0] == b[0]:
            return [a[1], b[1]]
        return [a[1] + (0.5 - a[0]) / (b[0] - a[0]) * (b[1] - a[1])]

    def motion_valid(a: np.ndarray, b: np.ndarray) -> bool:
        return all(GAP_Y[0] <= y <= GAP_Y[1] for y in crossing_ys(a, b))

    result = rrt_connect(SQUARE_LOW, SQUARE_HIGH, lambda q: True, motion_valid, START, GOAL, seed=2, time_limit=10.0)
    assert result.found, result.message
    assert np.array_equal(result.path[0], START) and np.array_equal(result.path[-1], GOAL)
    crossings = [y for a, b in zip(result.path[:-1], result.path[1:]) for y in crossing_ys(a, b)]
    assert crossings and all(GAP_Y[0] <= y <= GAP_Y[1] for y in crossings), crossings


def test_seven_dimensions_around_a_box():
    low, high = np.full(7, -np.pi), np.full(7, np.pi)
    block = (np.array([-0.5, -1.0, -1.0, -np.pi, -np.pi, -np.pi, -np.pi]), np.array([0.5, 1.0, 1.0, 1.0, np.pi, np.pi, np.pi]))
    boxes = [block]
    state_valid, motion_valid = checkers(boxes)
    start, goal = np.zeros(7), np.zeros(7)
    start[0], goal[0] = -2.0, 2.0
    result = rrt_connect(low, high, state_valid, motion_valid, start, goal, seed=4, time_limit=10.0)
    assert_free_path(result, start, goal, boxes)
    assert result.path.shape[1] == 7


@pytest.mark.parametrize(("change", "words"), [
    ({"lower": np.zeros(3)}, "same length"),
    ({"upper": np.array([1.0, 0.0])}, "lower < upper"),
    ({"start": np.zeros(3)}, "start must have shape"),
    ({"goal": np.array([0.5, 1.5])}, "goal is outside the bounds"),
    ({"start": np.array([np.nan, 0.1])}, "start is outside the bounds"),
    ({"seed": -1}, "seed"),
    ({"time_limit": 0.0}, "time_limit"),
    ({"range_": -0.1}, "range_"),
])
def test_bad_inputs_raise_value_error(change, words):
    state_valid, motion_valid = checkers(wall_boxes(gap=True))
    args = {"lower": SQUARE_LOW, "upper": SQUARE_HIGH, "start": START, "goal": GOAL, "seed": 1,
            "time_limit": 1.0, "range_": 0.0} | change
    with pytest.raises(ValueError, match=words):
        rrt_connect(args["lower"], args["upper"], state_valid, motion_valid, args["start"], args["goal"],
                    seed=args["seed"], time_limit=args["time_limit"], range_=args["range_"])


def test_a_reconnection_across_an_invalid_span_may_end_at_any_later_node_of_the_path():
    """Across the invalid span of the last path (its first and last invalid edges), the reconnection starts at the valid
    node before it and may end at the first valid node after it or any later one, the goal included: where no detour
    rejoins the path just past the span (a vase beside the exchange on the shelf task), RRTConnect joins it further on."""
    from planner.motion.transit import LazyTransit

    transit = object.__new__(LazyTransit)  # the span's case reads nothing of the query
    path = [40, 7, 12, 3, 25, 41]  # start 40, goal 41; edges 7-12 and 12-3 invalid
    assert transit._reconnection((path, (1, 2)), 40, 41) == (7, [3, 25, 41])
    assert transit._reconnection((path, (4, 4)), 40, 41) == (25, [41])


class _Walls:
    """A transit validity in the unit square: a state outside every box, a motion as `checkers` checks it."""

    def __init__(self, boxes):
        self.state, self.motion = checkers(boxes)

    def state_valid(self, q: np.ndarray) -> bool:
        return self.state(np.asarray(q, float))

    def motion_valid(self, a: np.ndarray, b: np.ndarray, ends: bool = True) -> bool:
        return self.motion(np.asarray(a, float), np.asarray(b, float))


def _behind_a_wall(closed: bool):
    """A query whose start (0.2, 0.5) sees no roadmap node: a wall at x 0.30-0.35 over y 0.15-0.85 hides the nodes (a
    grid at x >= 0.6, y 0.3-0.7), and a closed box around the start hides everything."""
    import types

    from planner.motion.graph import MotionGraph
    from planner.motion.space import JointSpace

    xs, ys = np.meshgrid([0.6, 0.75, 0.9], [0.3, 0.5, 0.7])
    nodes = np.stack([xs.ravel(), ys.ravel()], axis=1)
    edges = np.array([(i, j) for i in range(len(nodes)) for j in range(i + 1, len(nodes))
                      if np.linalg.norm(nodes[i] - nodes[j]) < 0.21])
    roadmap = types.SimpleNamespace(node_q=nodes, edges=edges, edge_valid=np.ones(len(edges), dtype=bool))
    space = JointSpace.of(np.zeros(2), np.ones(2), np.arange(2), np.zeros(2))
    return MotionGraph(roadmap), space, _Walls(walls_of(closed)), np.array([0.2, 0.5]), np.array([0.9, 0.5])


@pytest.mark.parametrize("closed", [False, True])
def test_an_end_no_graph_edge_joins_is_reconnected_once_with_the_baselines_budget(closed):
    """A start behind a wall that hides every node: the graph cannot help, so the query is RRTConnect's alone, with the
    baseline's budget (`rrt_motions`), once: found around the wall though a reconnection's budget (one motion here)
    could not find it; where the start is boxed in, the query fails after that one search."""
    from planner.motion.transit import LazyTransit, TransitFailed, TransitStats

    graph, space, walls, start, goal = _behind_a_wall(closed)
    stats = TransitStats()
    transit = LazyTransit(graph, space, walls, walls, walls, _transit_params(np.inf), np.random.default_rng(0), stats)
    if closed:
        with pytest.raises(TransitFailed, match="1 RRT reconnections"):
            transit.query(start, goal)
        assert stats.rrt_calls == 1
        return
    path = transit.query(start, goal)
    assert stats.rrt_calls == 1 and stats.ends_alone == 2  # the goal is not joined either: the start's RRTConnect reaches it
    assert np.array_equal(path[0], start) and np.array_equal(path[-1], goal)
    for a, b in zip(path[:-1], path[1:]):  # free at ten times the checker's resolution
        assert np.all(clearance(segment_points(a, b, STEP / 10), walls_of(closed)) > 0.0)


class _Counting(_Walls):
    """_Walls recording every motion it checks."""

    def __init__(self, boxes):
        super().__init__(boxes)
        self.motions: list[tuple[np.ndarray, np.ndarray]] = []

    def motion_valid(self, a: np.ndarray, b: np.ndarray, ends: bool = True) -> bool:
        self.motions.append((np.asarray(a, float), np.asarray(b, float)))
        return super().motion_valid(a, b, ends)


@pytest.mark.parametrize("max_join, alone", [(np.inf, 0), (0.2, 0), (0.1, 2)])
def test_an_end_is_joined_only_to_nodes_within_max_join(max_join, alone):
    """The same nodes, the start (0.45, 0.5) in front of the wall, 0.15 from the nearest node, and a post before the
    goal: the straight motion hits the post, an edge joins each end to a node, and the graph goes around it (no
    RRTConnect call, no end alone); with `max_join` below 0.15 no edge from the start is even checked (both ends count
    alone and RRTConnect joins them at once). Every join tried is within `max_join`; the path is re-checked apart."""
    from planner.motion.transit import LazyTransit, TransitStats

    graph, space, _, _, goal = _behind_a_wall(False)
    boxes = walls_of(False) + [(np.array([0.80, 0.45]), np.array([0.85, 0.55]))]
    walls, start = _Counting(boxes), np.array([0.45, 0.5])
    stats = TransitStats()
    path = LazyTransit(graph, space, walls, walls, walls, _transit_params(max_join), np.random.default_rng(0), stats).query(start, goal)
    nodes = graph.q[: graph.n_roadmap]
    joins = [(a, b) for a, b in walls.motions[1:]  # after the straight motion from the start to the goal (a node too)
             if any(np.array_equal(a, end) for end in (start, goal)) and np.any(np.all(nodes == b, axis=1))]
    assert stats.ends_alone == alone and stats.rrt_calls == (1 if alone else 0)
    assert all(np.linalg.norm(b - a) <= max_join for a, b in joins) and bool(joins) == (not alone)
    assert np.array_equal(path[0], start) and np.array_equal(path[-1], goal)
    for a, b in zip(path[:-1], path[1:]):  # free at ten times the checker's resolution
        assert np.all(clearance(segment_points(a, b, STEP / 10), boxes) > 0.0)


def _transit_params(max_join: float):
    """The transit parameters of the wall scenes: reconnections with one motion, the baseline's budget 3000."""
    from planner.motion.transit import TransitParams

    return TransitParams(connections=4, max_connections=8, max_join=max_join, max_searches=60, max_reconnections=2,
                         reconnect_motions=1, away_motions=1, rrt_motions=3000, rrt_step=0.1, shortcut_attempts=0,
                         shortcut_min_gain=0.0, graph_shortcut_length=np.inf, goal_nodes=16)


def walls_of(closed: bool):
    """The boxes of `_behind_a_wall`, for the independent re-check."""
    boxes = [(np.array([0.30, 0.15]), np.array([0.35, 0.85]))]
    return boxes if not closed else boxes + [(np.array([0.05, 0.10]), np.array([0.35, 0.15])),
                                             (np.array([0.05, 0.85]), np.array([0.35, 0.90])),
                                             (np.array([0.05, 0.10]), np.array([0.10, 0.90]))]
