"""The regrasp graph's search (planner/regrasp/graph.py) on a small hand-made graph in a 2-D joint space, its costs
worked out by hand: sequences come cheapest first, a lazy edge is made only when popped and one that cannot be made is
counted with its reason, and each sequence is named by its strategy."""
from __future__ import annotations

import numpy as np

from planner.regrasp.graph import FINAL, GOAL, INITIAL, START, CostModel, Edge, Node, Search
from planner.regrasp.task_graph import same_grasp

A, B = "right", "left"
PICKED = Node(A, "pick", 0, INITIAL)
AT_FINAL = Node(B, "place", 0, FINAL)
SET = Node(A, "pick", 0, 0)
TAKEN = Node(B, "place", 0, 0)
RETAKEN = Node(A, "place", 1, 0)  # the same hand again, in another grasp
AT_FINAL_SAME = Node(A, "place", 1, FINAL)


def q(*x: float) -> np.ndarray:
    return np.array([x], float)


class Calls:
    """Lazy edges' makers that count their calls."""

    def __init__(self) -> None:
        self.made: list[str] = []

    def maker(self, name: str, result: np.ndarray | None):
        def make() -> np.ndarray | None:
            self.made.append(name)
            return result
        return make


def place_left(node: Node) -> int:
    """The contact motions left at least: the place's two once the object is held at the final placement."""
    return 2 if node.hand and node.at == FINAL else 0


def expand_with(calls: Calls):
    def expand(node: Node, path) -> list[Edge]:
        if node == START:
            return [Edge("pick", PICKED, 2, q(1, 0))]
        if node == PICKED:
            return [Edge("handover", AT_FINAL, 6, np.vstack([q(1, 1), q(0, 1)]), rank=3),
                    Edge("set down", SET, 2, make=calls.maker("set down", q(2, 0)), why="cannot set down"),
                    Edge("set down", Node(A, "pick", 0, 1), 2, make=calls.maker("nowhere", None), why="cannot set down")]
        if node == SET:
            return [Edge("take", TAKEN, 4, make=calls.maker("take", q(2, 1)), why="cannot take"),
                    Edge("take", RETAKEN, 30, make=calls.maker("retake", q(2, 0)), why="cannot take")]
        if node in (TAKEN, RETAKEN):
            return [Edge("carry", Node(node.hand, "place", node.grasp, FINAL), 2, q(0, 1))]
        return [Edge("place", GOAL, 2, q(0, 0))]
    return expand


def test_sequences_come_cheapest_first_with_lazy_edges_made_when_popped():
    calls = Calls()
    search = Search(CostModel(velocity=1.0, contact=1.0), expand_with(calls), np.zeros(2), np.zeros(2), place_left)
    sequences = search.sequences()
    first = next(sequences)
    # pick 1 + 2; hand over 1 + 1 + 6; place 1 + 2: 14 s
    assert first.strategy == "handover" and abs(first.seconds - 14.0) < 1e-9
    assert [t.kind for t in first.transitions] == ["pick", "handover", "place"] and first.transitions[1].rank == 3
    assert first.describe()[1] == {"kind": "handover", "hand": B, "grasps": "place", "grasp": 0, "at": FINAL, "seconds": 8.0,
                                   "double_grasp": 3}
    # what was queued below 14 s, with the straight distance to the goal from where it starts, was made: both set-downs
    # (3 + 2 + 1) and the take (6 + 4 + 2); not the same hand's retake (6 + 30 + 2)
    assert sorted(calls.made) == ["nowhere", "set down", "take"]
    assert search.dropped == {"cannot set down": 1}
    second = next(sequences)
    # pick 3; set down 1 + 2; take 1 + 4; carry 2 + 2; place 1 + 2: 18 s, through the table with the other hand
    assert second.strategy == "table" and abs(second.seconds - 18.0) < 1e-9
    assert [t.kind for t in second.transitions] == ["pick", "set down", "take", "carry", "place"]
    third = next(sequences)
    # pick 3; set down 3; retake 0 + 30; carry sqrt(5) + 2; place 3: the same hand again
    assert third.strategy == "regrasp" and abs(third.seconds - (3 + 3 + 30 + 2 + np.sqrt(5) + 3)) < 1e-9
    assert "retake" in calls.made and next(sequences, None) is None


def test_a_graph_without_a_way_to_the_goal_gives_no_sequence():
    calls = Calls()

    def expand(node: Node, path) -> list[Edge]:
        return [Edge("pick", PICKED, 2, q(1, 0))] if node == START else [
            Edge("set down", SET, 2, make=calls.maker("nowhere", None), why="cannot set down")] if node == PICKED else []
    search = Search(CostModel(1.0, 1.0), expand, np.zeros(2), np.zeros(2), place_left)
    assert list(search.sequences()) == [] and search.dropped == {"cannot set down": 1} and search.expanded == 2


def test_a_palm_pose_turned_or_moved_past_the_tolerance_is_another_grasp():
    def turned(angle: float, shift: float) -> np.ndarray:
        c, s = np.cos(angle), np.sin(angle)
        return np.array([[c, -s, 0.0, shift], [s, c, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])

    assert same_grasp(np.eye(4), turned(0.1, 0.012)) and same_grasp(turned(0.3, 0.0), turned(0.0, 0.0))
    assert not same_grasp(np.eye(4), turned(0.4, 0.0)) and not same_grasp(np.eye(4), turned(0.0, 0.04))
    assert not same_grasp(np.eye(4), turned(np.pi, 0.0))
