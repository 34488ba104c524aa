"""The offline roadmap (paper V-A): Super Graph validity against the full model, the local planner's
resolution against a thin wall, queries, determinism, the tree variant and the cache."""
from __future__ import annotations

import dataclasses
import time

import numpy as np
import pytest

from planner.collision import build_collision_model
from planner.environment import Obstacle
from planner.geometry import pose
from planner.roadmap import Roadmap, RoadmapParams, RoadmapPlanner, roadmap_for
from planner.roadmap.build import build_roadmap, roadmap_collision_model, segment_checker
from planner.roadmap.local_planner import van_der_corput
from planner.roadmap.super_graph import components

SMALL = RoadmapParams(nodes=7, max_failures=100)


@pytest.fixture(scope="module")
def small(default_scene) -> Roadmap:
    return build_roadmap(default_scene, SMALL, seed=11)


@pytest.fixture(scope="module")
def reference(default_scene):
    """An independent checker: a fresh collision model with the project's default margins, every pair."""
    return build_collision_model(default_scene.robot, default_scene.environment, use_cache=False).checker()


def _dense_free(checker, qa, qb, n: int) -> bool:
    return not any(checker.in_collision(qa + t * (qb - qa), "all") for t in np.linspace(0.0, 1.0, n))


def test_every_super_graph_node_and_edge_is_free_in_the_full_model(default_scene, small, reference):
    """Nodes, and edges re-checked 10x finer than the roadmap's own resolution, on every pair of the full model."""
    assert len(small.node_q) > 40 and len(small.edges) > 20
    for q in small.node_q:
        assert not reference.in_collision(q, "all")
    cm, _ = roadmap_collision_model(default_scene, SMALL)
    seg = segment_checker(cm, SMALL)
    for u, v in small.edges:
        n = 10 * int(seg.steps(small.node_q[u], small.node_q[v], "moving")[0])
        assert _dense_free(reference, small.node_q[u], small.node_q[v], n), f"edge {u}-{v} collides between its checks"


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


def test_thin_wall_between_two_configurations_is_never_crossed(default_scene):
    """A 4 mm wall across a straight arm motion, wherever it stands along the motion, stops the segment."""
    robot = default_scene.robot
    arm = robot.spec.arms[0]
    idx = robot.arm_idx[arm.name]
    qa = robot.q_rest.copy()
    qa[idx[0]] -= 1.2  # the arm raised forwards, elbow bent
    qa[idx[3]] = -1.0
    qb = qa.copy()
    qb[idx[2]] -= 1.2  # the hand sweeps sideways
    subset = f"sub/{arm.name}"
    cm, _ = roadmap_collision_model(default_scene, SMALL)
    assert segment_checker(cm, SMALL).segment_free(qa, qb, subset), "without the wall the motion is free"
    palm = arm.hand.prefixed(arm.hand.palm_frame)
    for t in np.linspace(0.35, 0.65, 7):
        p0, p1 = (robot.frame_placement(qa + s * (qb - qa), palm)[:3, 3] for s in (t - 0.01, t + 0.01))
        yaw = np.arctan2(*(p1 - p0)[1::-1])
        wall = Obstacle("wall", "box", (0.004, 0.08, 0.08), pose((p0 + p1) / 2, (0.0, 0.0, yaw)))  # thin along the motion
        cm, _ = roadmap_collision_model(dataclasses.replace(default_scene, environment=(wall,)), SMALL)
        seg = segment_checker(cm, SMALL)
        assert seg.free(qa, subset) and seg.free(qb, subset), "the wall must leave both ends free"
        assert not seg.segment_free(qa, qb, subset), f"the wall at {t:.2f} of the motion was missed"


def test_query_path_starts_and_ends_where_asked_and_is_free(default_scene, small, reference):
    planner = RoadmapPlanner(default_scene, small, SMALL)
    start = default_scene.q_initial
    near = planner._connections(start, 30, 1)
    assert near, "the start must connect to the small roadmap"
    same = np.flatnonzero(small.node_component == small.node_component[near[0]])
    goal_node = same[np.argmax(np.linalg.norm(small.node_q[same] - start, axis=1))]
    goal = small.node_q[goal_node]
    result = planner.query(start, goal)
    assert result.found, result.message
    assert np.array_equal(result.path[0], start) and np.array_equal(result.path[-1], goal)
    for qa, qb in zip(result.path[:-1], result.path[1:]):
        n = 10 * int(planner.seg.steps(qa, qb, "moving")[0])
        assert _dense_free(reference, qa, qb, n)
    assert len(planner.graph.q) == len(small.node_q), "a query must leave the graph as it was"


def test_graph_edges_can_be_invalidated(default_scene, small):
    planner = RoadmapPlanner(default_scene, small, SMALL)
    u, v = small.edges[0]
    assert planner.graph.shortest_path(int(u), int(v)) == [u, v]
    planner.graph.invalidate([0])
    assert planner.graph.shortest_path(int(u), int(v)) != [u, v]


def test_same_seed_same_roadmap(default_scene, small):
    again = build_roadmap(default_scene, SMALL, seed=11)
    for f in dataclasses.fields(Roadmap):
        if f.name not in ("timings", "checks"):
            a, b = getattr(small, f.name), getattr(again, f.name)
            assert np.array_equal(a, b) if isinstance(a, np.ndarray) else a == b, f.name
    assert small.checks == again.checks


def test_tree_variant_is_a_forest_over_the_same_components(default_scene, small):
    tree = build_roadmap(default_scene, dataclasses.replace(SMALL, tree=True), seed=11)
    assert np.array_equal(tree.node_q, small.node_q)
    n_comp = len(np.unique(tree.node_component))
    assert len(tree.edges) == len(tree.node_q) - n_comp, "a forest has one edge fewer than nodes per component"
    assert n_comp == len(np.unique(small.node_component))
    assert tree.checks["sg_edges"] < small.checks["sg_edges"]


def test_cache_round_trip(default_scene):
    params = dataclasses.replace(SMALL, nodes=4)
    built, cached = roadmap_for(default_scene, params, seed=5, use_cache=False)
    assert not cached
    t = time.perf_counter()
    loaded, cached = roadmap_for(default_scene, params, seed=5)
    assert cached and time.perf_counter() - t < 1.0
    for f in dataclasses.fields(Roadmap):
        a, b = getattr(built, f.name), getattr(loaded, f.name)
        assert np.array_equal(a, b) if isinstance(a, np.ndarray) else a == b, f.name


def test_van_der_corput_visits_every_step_once():
    for n in (2, 3, 10, 257):
        s = van_der_corput(n)
        assert s[0] == 0.0 and s[1] == 1.0 and np.allclose(np.sort(s), np.linspace(0, 1, n))


def test_roadmap_command_prints_the_table_and_writes_json(tmp_path, capsys):
    import json

    from workbench.cli import main

    out = tmp_path / "roadmap.json"
    assert main(["roadmap", "--nodes", "4", "--seed", "2", "--json", str(out)]) == 0
    assert "collision checks" in capsys.readouterr().out
    data = json.loads(out.read_text())
    for key in ("nodes", "edges", "components", "collision_checks", "seconds", "elementary_nodes", "resolution"):
        assert key in data
    assert set(data["elementary_nodes"]) == {"right", "left"} and not data["cached"]
    assert main(["roadmap", "--nodes", "4", "--seed", "2", "--json", str(out)]) == 0
    again = json.loads(out.read_text())
    assert again["cached"] and again["wall_seconds"] < 1.0 and again["nodes"] == data["nodes"]


@pytest.mark.slow
def test_default_super_graph_size(default_scene, reference):
    """Two elementary roadmaps of 50 nodes give >= 1,700 Super Graph nodes; a sample of edges re-checked densely."""
    roadmap = build_roadmap(default_scene, RoadmapParams(), seed=0)
    stats = roadmap.stats()
    assert stats["elementary_nodes"] == {"right": 50, "left": 50}
    assert stats["nodes"] >= 1700
    print(stats)
    cm, _ = roadmap_collision_model(default_scene, RoadmapParams())
    seg = segment_checker(cm, RoadmapParams())
    rng = np.random.default_rng(0)
    for u, v in roadmap.edges[rng.choice(len(roadmap.edges), 40, replace=False)]:
        n = 3 * int(seg.steps(roadmap.node_q[u], roadmap.node_q[v], "moving")[0])
        assert _dense_free(reference, roadmap.node_q[u], roadmap.node_q[v], n)
