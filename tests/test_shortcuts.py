"""Shortcutting a transit's path (transit.py): the joint space it moves in, straight shortcuts between valid states,
none checked that gains too little or spans too much, the farthest vertex reached first, a detour made online cut."""
from __future__ import annotations

import numpy as np
import pytest

from planner.motion.space import JointSpace
from planner.motion.transit import shortcut


def test_joint_space_holds_and_reduces():
    base = np.arange(6.0)
    space = JointSpace.of(np.full(6, -10.0), np.full(6, 10.0), np.array([1, 3]), base)
    q = space.full(np.array([[7.0, 8.0]]))[0]
    assert q.tolist() == [0.0, 7.0, 2.0, 8.0, 4.0, 5.0]
    assert space.holds(q) and not space.holds(q + 1)
    assert space.distance(base, q) == pytest.approx(np.hypot(6.0, 5.0))
    with pytest.raises(ValueError):
        space.base[0] = 1.0


def test_shortcuts_start_and_end_at_valid_states():
    """A point inside a checked segment need not be a valid state (between two checks it keeps the clearance, not the
    padding): a shortcut from it would not keep its guarantee. Here the path crosses a band of such points; no
    shortcut may start or end in it."""
    band = (0.3, 0.6)  # x range of states too near something to start a motion from
    wall = np.array([0.5, 0.9])  # a disc no motion may cross

    class Rule:
        def state_valid(self, q):
            return not band[0] < q[0] < band[1]

        def motion_valid(self, qa, qb, ends=True):
            if ends and not (self.state_valid(qa) and self.state_valid(qb)):
                return False
            s = np.clip(np.dot(wall - qa, qb - qa) / max(np.dot(qb - qa, qb - qa), 1e-12), 0.0, 1.0)
            return bool(np.linalg.norm(qa + s * (qb - qa) - wall) > 0.2)

    path = np.array([[0.0, 0.0], [0.2, 0.1], [0.8, 0.1], [1.0, 0.0], [1.0, 1.0]])
    rule = Rule()
    for seed in range(20):
        out = shortcut(path, rule, rule, np.random.default_rng(seed), 16)
        assert np.allclose(out[0], path[0]) and np.allclose(out[-1], path[-1])
        new = [q for q in out if not any(np.allclose(q, p) for p in path)]
        assert all(rule.state_valid(q) for q in new), f"seed {seed}: a shortcut starts or ends inside the band"
        assert all(rule.motion_valid(a, b, ends=False) for a, b in zip(out[:-1], out[1:]))


class Counting:
    """Every state and motion valid; the motions asked about recorded."""

    def __init__(self):
        self.calls = []

    def state_valid(self, q):
        return True

    def motion_valid(self, qa, qb, ends=True):
        self.calls.append((qa.copy(), qb.copy()))
        return True

    def lengths(self) -> list[float]:
        return [float(np.linalg.norm(b - a)) for a, b in self.calls]


def test_shortcuts_gaining_too_little_are_not_checked():
    """A straight path has nothing to gain: with a minimum gain no shortcut of it is checked. On an L-shaped one (legs of
    1) shortcuts are checked, the first (one leg to the other) saving at least the minimum, and the path gets shorter."""
    straight = np.array([[0.0, 0.0], [0.5, 0.0], [1.0, 0.0], [2.0, 0.0]])
    rule = Counting()
    out = shortcut(straight, rule, rule, np.random.default_rng(0), 16, min_gain=0.01)
    assert rule.calls == [] and np.array_equal(out, straight)
    corner = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    for seed in range(10):
        rule = Counting()
        path = shortcut(corner, rule, rule, np.random.default_rng(seed), 16, min_gain=0.1)
        assert rule.calls, f"seed {seed}: no shortcut of the corner was checked"
        a, b = rule.calls[0]  # the first: from the first leg (y = 0) to the second (x = 1), saving at least 0.1
        assert a[1] == 0.0 and b[0] == 1.0 and (1.0 - a[0]) + b[1] - np.linalg.norm(b - a) >= 0.1 - 1e-12
        assert np.linalg.norm(np.diff(path, axis=0), axis=1).sum() < 2.0


def test_vertex_shortcuts_jump_to_the_farthest_reachable_vertex_and_check_each_kept_motion_once():
    """A zigzag around a wall: the greedy pass jumps from each vertex to the farthest one a valid straight motion
    reaches; here that keeps as few vertices as a breadth-first search over all chains of valid jumps (the oracle, which
    shares no code). Every kept motion is valid and checked once, near the ends (from the first vertex, to the last) by
    the `near` validity. A nearly straight stretch is taken as it is, unchecked."""
    from planner.motion.transit import shortcut_vertices

    wall = (np.array([2.0, -1.0]), np.array([2.0, 0.5]))  # a segment no motion may cross

    def crosses(qa, qb):
        (p, r), d = wall, qb - qa
        den = d[0] * (r - p)[1] - d[1] * (r - p)[0]
        if abs(den) < 1e-12:
            return False
        t = ((p - qa)[0] * (r - p)[1] - (p - qa)[1] * (r - p)[0]) / den
        u = ((p - qa)[0] * d[1] - (p - qa)[1] * d[0]) / den
        return 0.0 <= t <= 1.0 and 0.0 <= u <= 1.0

    class Rule(Counting):
        """Counting's, the motions crossing the wall invalid, each recorded as a pair of tuples."""

        def motion_valid(self, qa, qb, ends=True):
            self.calls.append((tuple(qa), tuple(qb)))
            return not crosses(qa, qb)

    path = np.array([[0, 0], [1, -0.5], [1.5, 1], [2, 1.2], [2.5, 1], [3, -0.5], [4, 0], [5, 0.5], [6, 0]], dtype=float)
    full, near = Rule(), Rule()
    out = shortcut_vertices(path, full, near)
    # the oracle: fewest vertices over chains of valid jumps, breadth first
    n, best, frontier = len(path), {0: [0]}, [0]
    while n - 1 not in best:
        reached = []
        for i in frontier:
            for j in range(i + 1, n):
                if j not in best and not crosses(path[i], path[j]):
                    best[j] = best[i] + [j]
                    reached.append(j)
        frontier = reached
    assert len(out) == len(best[n - 1]) < len(path), (out, path[best[n - 1]])
    assert not any(crosses(a, b) for a, b in zip(out[:-1], out[1:]))
    kept = [(tuple(a), tuple(b)) for a, b in zip(out[:-1], out[1:])]
    calls = full.calls + near.calls
    assert all(calls.count(k) == 1 for k in kept), "each kept motion checked once"
    assert all(a == tuple(path[0]) or b == tuple(path[-1]) for a, b in near.calls)
    assert all(a != tuple(path[0]) and b != tuple(path[-1]) for a, b in full.calls)
    straight = np.array([[0.0, 0.0], [1.0, 0.01], [2.0, 0.0], [3.0, 0.01]])
    rule = Rule()
    assert np.array_equal(shortcut_vertices(straight, rule, rule, min_gain=0.1), straight) and rule.calls == []


def test_shortcuts_longer_than_the_limit_are_never_checked():
    """A graph path keeps its edges rather than try a long new motion: with `max_length`, no motion checked by either
    shortcut pass is longer than it (every motion valid here), the path's vertices stay where no short jump reaches,
    and without it the greedy pass jumps straight from the first vertex to the last."""
    from planner.motion.transit import shortcut_vertices

    zigzag = np.array([[0.0, 0.0], [0.6, 0.6], [1.2, 0.0], [1.8, 0.6], [2.4, 0.0], [3.0, 0.6]])
    rule = Counting()
    out = shortcut(shortcut_vertices(zigzag, rule, rule, 0.05, 1.0), rule, rule, np.random.default_rng(0), 50, 0.05, 1.0)
    assert rule.calls and max(rule.lengths()) <= 1.0
    assert np.linalg.norm(out[-1] - out[0]) > 1.0 and len(out) > 2
    rule = Counting()
    assert len(shortcut_vertices(zigzag, rule, rule, 0.05)) == 2 and max(rule.lengths()) > 3.0


def test_a_detour_made_online_is_cut_however_long():
    """The length limit keeps roadmap edges only: a jump that would replace part of a detour RRTConnect made (checked
    over every pair, as the jump would be) is tried whatever its length; the random pass keeps each piece's flag as it
    splices."""
    from planner.motion.transit import kept_detours, shortcut_vertices

    zigzag = np.array([[0.0, 0.0], [0.6, 0.6], [1.2, 0.0], [1.8, 0.6], [2.4, 0.0], [3.0, 0.6]])
    roadmap = np.zeros(5, dtype=bool)
    rule = Counting()
    assert len(shortcut_vertices(zigzag, rule, rule, 0.05, 1.0, roadmap)) == 6 and max(rule.lengths(), default=0.0) <= 1.0
    detour = roadmap.copy()
    detour[2] = True  # the middle segment came from a reconnection
    rule = Counting()
    out = shortcut_vertices(zigzag, rule, rule, 0.05, 1.0, detour)
    assert len(out) == 2 and max(rule.lengths()) > 3.0
    flags = kept_detours(zigzag, detour, zigzag[[0, 1, 2, 3, 5]])
    assert flags.tolist() == [False, False, True, False]  # the jump 3 -> 5 is new; the others are the path's own
    rule = Counting()
    shortcut(zigzag, rule, rule, np.random.default_rng(0), 200, 0.05, 1.0, detour)
    assert max(rule.lengths()) > 1.0  # some random shortcut over the detour is longer than the limit
    rule = Counting()
    shortcut(zigzag, rule, rule, np.random.default_rng(0), 200, 0.05, 1.0, roadmap)
    assert max(rule.lengths()) <= 1.0
