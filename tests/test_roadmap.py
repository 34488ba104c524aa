"""The offline roadmap (paper V-A): Super Graph validity against an independent oracle (which catches a checker
blind to the hands), the local planner's resolution against a thin wall, queries, determinism, the tree variant and
the cache."""
from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path

import numpy as np
import pytest
from oracle import Oracle
from sandbox import forbid

from planner.collision.schedule import coarse_first, two_level, van_der_corput
from planner.collision.segments import SegmentChecker
from planner.core.results import save_result
from planner.model.environment import Obstacle
from planner.model.geometry import pose
from planner.motion.graph import INVALID, MotionGraph, PhaseStatus
from planner.motion.query import RoadmapQuery
from planner.roadmap import Roadmap, RoadmapParams, roadmap_for
from planner.roadmap import build as roadmap_build
from planner.roadmap.build import build_roadmap, roadmap_collision_model, segment_checker
from planner.roadmap.step import session_roadmap_seed
from planner.roadmap.super_graph import components, edge_candidates, node_candidates

SMALL = RoadmapParams(nodes=7, max_failures=100, task_nodes=0)  # Vis-PRM alone: the task sites have tests of their own
SESSION_SEED = 3  # the seed of the session tests' plans (test_session.py)
ORACLE_STEP = 0.01  # rad: the oracle's own resolution along an edge (largest joint change between two of its checks)


@pytest.fixture(scope="module")
def small(default_scene) -> Roadmap:
    return build_roadmap(default_scene, SMALL, seed=11)[0]


@pytest.fixture(scope="module")
def oracle(default_scene) -> Oracle:
    """The independent oracle (tests/oracle.py): full URDF meshes through python-fcl, no code shared with the checker."""
    return Oracle(default_scene)


def _segment_collisions(oracle: Oracle, qa: np.ndarray, qb: np.ndarray) -> list[str]:
    """The oracle's collisions along the straight segment qa -> qb, at its own resolution (ends included)."""
    n = max(2, math.ceil(np.abs(qb - qa).max() / ORACLE_STEP) + 1)
    return [hit for t in np.linspace(0.0, 1.0, n) for hit in oracle.robot_collisions(qa + t * (qb - qa))]


def _roadmap_collisions(oracle: Oracle, roadmap: Roadmap) -> list[str]:
    """Every node's and edge's collisions by the oracle, named by node or edge."""
    found = [f"node {n}: {hit}" for n, q in enumerate(roadmap.node_q) for hit in oracle.robot_collisions(q)]
    for u, v in roadmap.edges:
        found += [f"edge {u}-{v}: {hit}" for hit in _segment_collisions(oracle, roadmap.node_q[u], roadmap.node_q[v])]
    return found


@pytest.mark.slow
def test_every_super_graph_node_and_edge_is_free_by_the_oracle(small, oracle):
    """Nodes, and edges re-checked at the oracle's own resolution, with the URDFs' own meshes."""
    assert len(small.node_q) > 40 and len(small.edges) > 20
    found = _roadmap_collisions(oracle, small)
    assert not found, f"{len(found)} collisions, first: {found[:3]}"


@pytest.mark.slow
def test_the_oracle_catches_a_checker_blind_to_hand_obstacle_pairs(default_scene, oracle, monkeypatch):
    """The same roadmap built by a checker that skips every hand-obstacle pair is not free by the oracle."""
    real = roadmap_build.pair_subsets

    def blind(cm, dec):
        geoms = cm.geometry.geometryObjects
        part = [cm.parts[i] if i < cm.n_robot_geoms else "env" for i in range(len(geoms))]
        pairs = [(part[p.first], part[p.second]) for p in cm.geometry.collisionPairs]
        hand_env = np.array([a.endswith("_hand") and b == "env" or b.endswith("_hand") and a == "env" for a, b in pairs])
        assert hand_env.any()
        return {name: k[~hand_env[k]] for name, k in real(cm, dec).items()}

    monkeypatch.setattr(roadmap_build, "pair_subsets", blind)
    broken = build_roadmap(default_scene, SMALL, seed=11)[0]
    found = _roadmap_collisions(oracle, broken)
    hands = tuple(arm.hand.prefix for arm in default_scene.robot.spec.arms)
    obstacles = tuple(f" with {ob.name}" for ob in default_scene.environment)
    assert any(hit.split(": ", 1)[1].startswith(hands) and hit.endswith(obstacles) for hit in found), found[:3]


def test_super_graph_structure(small):
    """Nodes compose one elementary node per arm; edges follow elementary edges in both roadmaps (or switch the source)."""
    arms = small.arms
    elem = {tuple(sorted(e)) for e in small.elem_edges.tolist()}
    for a in (0, 1):
        ids = small.node_elem[:, a]
        assert np.all(small.elem_arm[ids] == a)
    for (u, v) in small.edges:
        for a in (0, 1):
            x, y = small.node_elem[u, a], small.node_elem[v, a]
            assert x == y or tuple(sorted((x, y))) in elem
        if np.all(small.node_elem[u] == small.node_elem[v]):
            assert small.node_common[u] != small.node_common[v]
    assert np.array_equal(small.node_component, components(len(small.node_q), small.edges))
    assert small.wrists.shape == (len(small.node_q), len(arms), 3)


def test_one_arm_edges_move_the_arm_whose_common_part_the_nodes_take():
    """Three nodes on arm 0's path, two on arm 1's: every (arm-0 edge, arm-1 node) and (arm-1 edge, arm-0 node) pair is
    an edge with that arm moving and its common part source, checked for the still arm against the rest."""
    node_elem, source = node_candidates(3, 2)
    e0, e1 = np.array([[0, 1], [1, 2]]), np.array([[0, 1]])
    arms = ("right", "left")
    both, _ = edge_candidates(node_elem, source, e0, e1, arms, mixed=False)
    cand, subsets = edge_candidates(node_elem, source, e0, e1, arms, mixed=False, one_arm=True)
    found = {(tuple(node_elem[u]), tuple(node_elem[v]), int(source[u]), int(source[v]), s)
             for (u, v), s in zip(cand, subsets) if (node_elem[u] == node_elem[v]).sum() == 1}  # one arm still
    expected = {((a, still), (b, still), 0, 0, "cross/left") for a, b in e0 for still in (0, 1)}
    expected |= {((still, a), (still, b), 1, 1, "cross/right") for a, b in e1 for still in (0, 1, 2)}
    assert found == expected
    assert len(cand) == len(both) + len(expected)


def test_other_arm_edges_move_the_arm_whose_common_part_the_nodes_do_not_take():
    """With `other_arm`, every (arm-1 edge, arm-0 node) pair in the half whose common part comes from arm 0 (and the
    converse) is an edge too, checked for the moving arm against the rest; without `both`, no edge moves both arms."""
    node_elem, source = node_candidates(3, 2)
    e0, e1 = np.array([[0, 1], [1, 2]]), np.array([[0, 1]])
    cand, subsets = edge_candidates(node_elem, source, e0, e1, ("right", "left"), mixed=False, one_arm=True, both=False,
                                    other_arm=True)
    found = {(tuple(node_elem[u]), tuple(node_elem[v]), int(source[u]), int(source[v]), s) for (u, v), s in zip(cand, subsets)}
    one = {((a, still), (b, still), 0, 0, "cross/left") for a, b in e0 for still in (0, 1)}
    one |= {((still, a), (still, b), 1, 1, "cross/right") for a, b in e1 for still in (0, 1, 2)}
    other = {((a, still), (b, still), 1, 1, "cross/right") for a, b in e0 for still in (0, 1)}
    other |= {((still, a), (still, b), 0, 0, "cross/left") for a, b in e1 for still in (0, 1, 2)}
    switch = {((x0, x1), (x0, x1), 0, 1, "mixed") for x0 in range(3) for x1 in range(2)}
    assert found == one | other | switch and len(cand) == len(found)


def test_super_graph_moves_one_arm_at_a_time_too(small):
    """A roadmap built with the default edge kinds has edges where one arm holds still besides those moving both."""
    still = (small.node_elem[small.edges[:, 0]] == small.node_elem[small.edges[:, 1]]).sum(axis=1) == 1
    assert still.any() and (~still).any()


@pytest.mark.parametrize("coarse", [1, 3, 5])
def test_thin_wall_between_two_configurations_is_never_crossed(default_scene, coarse):
    """A 4 mm wall across a straight arm motion, wherever it stands along the motion, stops the segment, also when the
    segment is checked coarse first (the wall lies between two coarse checks: only the dense ones near it can see it)."""
    robot = default_scene.robot
    arm = robot.spec.arms[0]
    idx = robot.arm_idx[arm.name]
    qa = robot.q_rest.copy()
    qa[idx[0]] -= 1.2  # the arm raised forwards, elbow bent
    qa[idx[3]] = -1.0
    qb = qa.copy()
    qb[idx[2]] -= 1.2  # the hand sweeps sideways
    subset = f"sub/{arm.name}"
    def checker(cm):  # the roadmap's own local planner, or one checking coarse first
        return segment_checker(cm, SMALL) if coarse == 1 else SegmentChecker(cm, SMALL.env_clearance, coarse=coarse)

    cm, _ = roadmap_collision_model(default_scene, SMALL)
    assert checker(cm).segment_free(qa, qb, subset), "without the wall the motion is free"
    palm = arm.hand.prefixed(arm.hand.palm_frame)
    for t in np.linspace(0.35, 0.65, 7):
        p0, p1 = (robot.frame_placement(qa + s * (qb - qa), palm)[:3, 3] for s in (t - 0.01, t + 0.01))
        yaw = np.arctan2(*(p1 - p0)[1::-1])
        wall = Obstacle("wall", "box", (0.004, 0.08, 0.08), pose((p0 + p1) / 2, (0.0, 0.0, yaw)))  # thin along the motion
        cm, _ = roadmap_collision_model(dataclasses.replace(default_scene, environment=(wall,)), SMALL)
        seg = checker(cm)
        assert seg.free(qa, subset) and seg.free(qb, subset), "the wall must leave both ends free"
        assert not seg.segment_free(qa, qb, subset), f"the wall at {t:.2f} of the motion was missed"


def test_query_path_starts_and_ends_where_asked_and_is_free(default_scene, small, oracle):
    """The robot-alone query (the motion's graph and lazy transit on the roadmap's own checks) from the initial
    configuration to the node of the largest component farthest from it: a path the oracle finds free, the graph
    left as it was."""
    query = RoadmapQuery(default_scene, small, SMALL)
    start = default_scene.q_initial
    largest = np.flatnonzero(small.node_component == np.argmax(np.bincount(small.node_component)))
    goal = small.node_q[largest[np.argmax(np.linalg.norm(small.node_q[largest] - start, axis=1))]]
    result = query.query(start, goal)
    assert result.found, result.message
    assert np.array_equal(result.path[0], start) and np.array_equal(result.path[-1], goal)
    assert result.checks > 0 and np.isclose(result.length, np.linalg.norm(np.diff(result.path, axis=0), axis=1).sum())
    for qa, qb in zip(result.path[:-1], result.path[1:]):
        assert not _segment_collisions(oracle, qa, qb)
    assert len(query.graph.q) == len(small.node_q), "a query must leave the graph as it was"
    moved = goal.copy()
    moved[np.setdiff1d(np.arange(len(goal)), query.space.idx)[0]] += 0.1
    with pytest.raises(ValueError, match="transit only"):
        query.query(start, moved)


def test_graph_edges_marked_invalid_are_avoided(small):
    graph = MotionGraph(small)
    status = PhaseStatus(graph)
    u, v = (int(n) for n in graph.edges[0])
    weights = np.ones(len(graph.edges))
    assert status.shortest_path(weights, u, v) == [u, v]
    status.edge[graph.edge_id(u, v)] = INVALID
    assert status.shortest_path(weights, u, v) != [u, v]


def _files(roadmap: Roadmap, folder: Path) -> dict[str, bytes]:
    """The roadmap's saved files, by name."""
    folder.mkdir()
    return {name: (folder / name).read_bytes() for name in save_result(roadmap, folder, "roadmap")}


def test_same_seed_same_roadmap(default_scene, small, tmp_path):
    """The same seed builds the same files; the edge stage's progress counts the candidates checked of all, and the
    edges kept, up to those of the result."""
    said: list[str] = []
    again = build_roadmap(default_scene, SMALL, seed=11, progress=lambda _, message="": said.append(message))[0]
    assert _files(again, tmp_path / "again") == _files(small, tmp_path / "small")
    counts = [tuple(int(x.replace(",", "")) for x in m.groups())
              for m in (re.fullmatch(r"Super Graph edges: ([\d,]+) of ([\d,]+) candidates checked, ([\d,]+) kept", s) for s in said) if m]
    assert len(counts) > 1 and counts == sorted(counts), said
    checked, total, kept = counts[-1]
    assert checked == total >= kept == len(again.edges)


def test_tree_variant_is_a_forest_over_the_same_components(default_scene, small):
    tree = build_roadmap(default_scene, dataclasses.replace(SMALL, tree=True), seed=11)[0]
    assert np.array_equal(tree.node_q, small.node_q)
    n_comp = len(np.unique(tree.node_component))
    assert len(tree.edges) == len(tree.node_q) - n_comp, "a forest has one edge fewer than nodes per component"
    assert n_comp == len(np.unique(small.node_component))
    assert tree.checks["sg_edges"] < small.checks["sg_edges"]


def test_cache_round_trip(default_scene, monkeypatch, tmp_path):
    """A built roadmap reports its stage seconds; the same one is then served by the cache (building is forbidden)."""
    params = dataclasses.replace(SMALL, nodes=4)
    built, seconds = roadmap_for(default_scene, params, seed=5, use_cache=False)
    assert set(seconds) == {"vis_prm", "sg_nodes", "sg_edges"}
    forbid(monkeypatch, "planner.roadmap.step.build_roadmap")
    loaded, seconds = roadmap_for(default_scene, params, seed=5)
    assert seconds == {}
    assert _files(loaded, tmp_path / "loaded") == _files(built, tmp_path / "built")


def test_van_der_corput_visits_every_step_once():
    for n in (2, 3, 10, 257):
        s = van_der_corput(n)
        assert s[0] == 0.0 and s[1] == 1.0 and np.allclose(np.sort(s), np.linspace(0, 1, n))


def test_roadmap_command_prints_the_table_and_writes_json(tmp_path, capsys, monkeypatch):
    import json

    from workbench.cli import main

    out = tmp_path / "roadmap.json"
    assert main(["roadmap", "--nodes", "4", "--task-nodes", "0", "--seed", "2", "--json", str(out)]) == 0
    assert "collision checks" in capsys.readouterr().out
    data = json.loads(out.read_text())
    for key in ("nodes", "edges", "components", "collision_checks", "stage_seconds", "elementary_nodes", "resolution"):
        assert key in data
    assert set(data["elementary_nodes"]) == {"right", "left"} and not data["cached"]
    assert set(data["stage_seconds"]) == {"vis_prm", "sg_nodes", "sg_edges"}
    forbid(monkeypatch, "planner.roadmap.step.build_roadmap")
    assert main(["roadmap", "--nodes", "4", "--task-nodes", "0", "--seed", "2", "--json", str(out)]) == 0
    again = json.loads(out.read_text())
    assert again["cached"] and again["stage_seconds"] == {} and again["nodes"] == data["nodes"]


@pytest.mark.slow
def test_default_super_graph_size(default_scene, oracle):
    """Two elementary roadmaps of 30 Vis-PRM nodes and up to 60 around the task's sites give thousands of Super Graph
    nodes, at least 97 % of them in one component; a sample of edges re-checked by the oracle. The roadmap of the
    session tests' seed: built here or by them, then taken from the shared test cache (one build)."""
    roadmap = roadmap_for(default_scene, RoadmapParams(), session_roadmap_seed(SESSION_SEED))[0]
    stats = roadmap.stats()
    assert all(60 <= n <= 90 for n in stats["elementary_nodes"].values()), stats["elementary_nodes"]
    assert stats["nodes"] >= 5000 and stats["largest_component"] >= 0.97 * stats["nodes"]
    rng = np.random.default_rng(0)
    for u, v in roadmap.edges[rng.choice(len(roadmap.edges), 40, replace=False)]:
        assert not _segment_collisions(oracle, roadmap.node_q[u], roadmap.node_q[v])


def test_coarse_first_never_passes_a_segment_that_comes_nearer_than_the_clearance():
    """Analytic: along a segment checked at n configurations, a pair's distance d(s) changes by at most 2 (p - c) between
    two of them (the resolution's bound). With clearance c = 0 and padding p = 1, a check fails where d < 1, a coarse one
    where d < k. A V-shaped dip as steep as the bound, anywhere, to any depth: the segment passes only if d stays >= c,
    and always passes when d stays >= p; far from everything it costs only the coarse checks."""
    rng = np.random.default_rng(5)
    for _ in range(3000):
        n, k = int(rng.integers(8, 80)), int(rng.integers(2, 6))
        s0, depth = rng.uniform(-0.2, 1.2), rng.uniform(-0.5, 1.5)

        def d(s):
            return depth + 2.0 * (n - 1) * abs(s - s0)

        calls = []

        def hits(s, coarse):
            calls.append(s)
            return d(s) < (k if coarse else 1.0)

        nearest = float(np.min(d(np.linspace(0.0, 1.0, 20 * n))))  # d over the grid, at once
        passed = coarse_first(n, k, hits) is None
        if passed:
            assert nearest >= 0.0, f"n={n} k={k}: passed with the pair {-nearest:.3f} deep"
        if nearest >= 1.0:
            assert passed, f"n={n} k={k}: failed though the pair stays beyond its padding"
        if nearest >= k:
            assert len(calls) == -(-(n - 1) // k) + 1 < n



@pytest.mark.slow
def test_two_level_never_passes_a_segment_that_comes_nearer_than_the_clearance():
    """Analytic, two grids in any ratio (a transit end held close: n checks at the transit paddings, m > n at the
    paddings fitted to it). Clearance c = 0, fine padding p = 1: between two of the m configurations a pair's distance
    changes by at most 2 (p - c), so between two of the n by 2 P with P = (m - 1) / (n - 1), the coarse padding. A
    V-shaped dip as steep as the bound, anywhere, to any depth: the segment passes only if d stays >= c, always when d
    stays >= p; far from everything it costs the n coarse checks alone. `ends=False`: the ends are not checked fine."""
    rng = np.random.default_rng(7)
    for _ in range(3000):
        n = int(rng.integers(2, 40))
        m = n + int(rng.integers(1, 400))
        coarse_padding = (m - 1) / (n - 1)
        s0, depth, ends = rng.uniform(-0.2, 1.2), rng.uniform(-0.5, 1.5 * coarse_padding), bool(rng.integers(2))

        def d(s):
            return depth + 2.0 * (m - 1) * abs(s - s0)

        calls = []

        def hits(s, coarse):
            calls.append((s, coarse))
            return d(s) < (coarse_padding if coarse else 1.0)

        if not ends and min(d(0.0), d(1.0)) < 1.0:
            continue  # the ends must be valid at the fine padding to be skipped
        nearest = float(np.min(d(np.linspace(0.0, 1.0, 20 * m))))  # d over the grid, at once
        passed = two_level(n, m, hits, ends) is None
        if passed:
            assert nearest >= 0.0, f"n={n} m={m}: passed with the pair {-nearest:.3f} deep"
        if nearest >= 1.0:
            assert passed, f"n={n} m={m}: failed though the pair stays beyond its padding"
        if nearest >= coarse_padding:
            assert sorted(calls) == [(j / (n - 1), True) for j in range(n)]


def test_two_level_tests_only_the_finer_pairs_between_coarse_configurations():
    """Analytic, two pairs, clearance 0: pair A padded 1 finely and (m - 1) / (n - 1) coarsely (fitted to a tight end),
    pair B padded alike at both (its dip as steep as the coarse grid allows). Between the coarse configurations only A
    is tested (`between`), and never at a coarse one: a segment passes only if both keep their clearance, since B passed
    at its padding at every coarse configuration, whether that one failed coarse or not."""
    rng = np.random.default_rng(8)
    passed_with_b_near = 0
    for _ in range(3000):
        n = int(rng.integers(2, 40))
        m = n + int(rng.integers(1, 400))
        coarse_a, pad_b = (m - 1) / (n - 1), rng.uniform(0.5, 3.0)
        s_a, s_b = rng.uniform(-0.2, 1.2, 2)
        depth_a, depth_b = rng.uniform(-0.5, 1.5 * coarse_a), rng.uniform(-0.5, 1.5 * pad_b)

        def d_a(s):
            return depth_a + 2.0 * (m - 1) * abs(s - s_a)

        def d_b(s):
            return depth_b + 2.0 * pad_b * (n - 1) * abs(s - s_b)

        between_calls = []

        def hits(s, coarse):
            return d_a(s) < (coarse_a if coarse else 1.0) or d_b(s) < pad_b

        def between(s):
            between_calls.append(s)
            return d_a(s) < 1.0

        grid = np.linspace(0.0, 1.0, 20 * m)  # d_a and d_b over it, at once
        near_a, near_b = float(np.min(d_a(grid))), float(np.min(d_b(grid)))
        if two_level(n, m, hits, True, between) is None:
            assert near_a >= 0.0 and near_b >= 0.0, f"n={n} m={m}: passed {near_a:.3f} / {near_b:.3f} from the clearance"
            passed_with_b_near += near_b < pad_b
        assert not any(abs(s * (n - 1) - round(s * (n - 1))) < 1e-9 for s in between_calls), "a coarse one tested as between"
    assert passed_with_b_near, "some segments must pass with B inside its padding between two coarse configurations"
