"""The roadmap made dense where the task's queries land (planner/roadmap/task_sites.py, task_prm.py): sites where each
arm reaches its placements and the exchange, nodes around them joined by short edges, components bridged; the nodes and
edges are free by the independent oracle, and the build is deterministic for a seed. Small roadmaps: a few nodes."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pinocchio as pin
import pytest
from oracle import Oracle

from planner.collision.checker import build_collision_model
from planner.handover.reach import fingertip_centre
from planner.roadmap import RoadmapParams
from planner.roadmap.build import build_roadmap, roadmap_collision_model, segment_checker
from planner.roadmap.decomposition import decompose
from planner.roadmap.task_prm import task_prm
from planner.roadmap.task_sites import HEIGHTS, TOLERANCE, task_sites
from planner.roadmap.vis_prm import Elementary

TINY = RoadmapParams(nodes=4, max_failures=40, task_nodes=6, site_starts=1)


@pytest.fixture(scope="module")
def sites(default_scene):
    dec = decompose(default_scene.robot)
    return dec, task_sites(default_scene, dec, build_collision_model(default_scene.robot, default_scene.environment).checker(), 1,
                           np.random.default_rng(0))


def _at(dec, idx: np.ndarray, values: np.ndarray) -> np.ndarray:
    q = dec.q_hold.copy()
    q[idx] = values
    return q


def _tip(robot, arm: str, q: np.ndarray) -> np.ndarray:
    """The open hand's fingertip centre in the world at q, by pinocchio's forward kinematics."""
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    return data.oMf[robot.frame_id(robot.palm_frame(arm))].act(fingertip_centre(robot, arm))


def test_each_arm_has_sites_at_rest_at_the_placement_it_reaches_and_at_one_exchange_point(default_scene, sites):
    """The default task: the right hand picks, the left places. Each site beyond the first two (the start and end
    configurations) brings the fingertip centre within the tolerance of a point above the object's centre of mass at the
    placement the arm reaches, or of one exchange point between the arms."""
    dec, found = sites
    robot, scene = default_scene.robot, default_scene
    com = np.asarray(scene.object_mesh.center_mass)
    at = {name: T[:3, :3] @ com + T[:3, 3] for name, T in (("initial", scene.object_initial), ("final", scene.object_final))}
    exchange = []
    for arm, placement in (("right", "initial"), ("left", "final")):
        values = found[arm]
        idx = dec.subsystem(arm)
        assert np.allclose(values[0], scene.q_initial[idx]) and np.allclose(values[1], scene.q_final[idx])
        tips = [_tip(robot, arm, _at(dec, idx, v)) for v in values[2:]]
        near = [[np.linalg.norm(t - at[placement] - [0, 0, h]) <= TOLERANCE + 1e-9 for t in tips] for h in HEIGHTS]
        assert all(any(n) for n in near), f"the {arm} arm has no site above its placement"
        other = at["final" if placement == "initial" else "initial"]
        assert not any(np.linalg.norm(t - other - [0, 0, h]) <= TOLERANCE for t in tips for h in HEIGHTS), \
            f"the {arm} arm cannot reach the other placement"
        exchange += [t for t, *by in zip(tips, *near) if not any(by)]
    assert exchange, "no exchange site"
    spread = np.ptp(np.array(exchange), axis=0)
    assert np.all(spread <= 2 * TOLERANCE + 1e-9), "the exchange sites are one point for both arms"


def test_task_nodes_are_free_their_edges_short_and_components_bridged(default_scene, sites):
    """Two far-apart nodes of a made-up elementary roadmap (two components) and the right arm's sites: 20 nodes added,
    are free, the median edge no longer than the task edge and none longer than the bridges' limit, and the roadmap one
    component (a node no bridge joins is dropped)."""
    dec, found = sites
    robot = default_scene.robot
    cm, _ = roadmap_collision_model(default_scene, TINY)
    seg = segment_checker(cm, TINY)
    idx = dec.subsystem("right")
    free = [v for v in found["right"] if seg.free(_at(dec, idx, v), "sub/right")]
    assert len(free) >= 3, "most sites are free at the roadmap's paddings"
    start = Elementary(np.stack([free[0], free[-1]]), np.zeros((0, 2), np.int64), np.ones(2, bool), 2)
    out = task_prm(seg, "sub/right", dec.q_hold, idx, robot.lower[idx], robot.upper[idx], start, found["right"],
                   np.random.default_rng(1), 20, 0.2, 0.8, 3, 5.0, 40)
    assert np.array_equal(out.nodes[:2], start.nodes) and 15 <= len(out.nodes) <= 22  # nodes no bridge joins are dropped
    checker = cm.checker()
    for v in out.nodes:
        assert not checker.in_collision(_at(dec, idx, v), cm.subsets["sub/right"])
    lengths = np.linalg.norm(out.nodes[out.edges[:, 0]] - out.nodes[out.edges[:, 1]], axis=1)
    assert np.all(lengths <= 5.0 + 1e-9) and np.median(lengths) <= 0.8
    parent = list(range(len(out.nodes)))

    def root(a: int) -> int:
        while parent[a] != a:
            a = parent[a]
        return a
    for u, v in out.edges:
        parent[root(int(u))] = root(int(v))
    assert len({root(i) for i in range(len(out.nodes))}) == 1, "the components were not bridged"


@pytest.mark.slow
def test_a_small_task_roadmap_is_free_by_the_oracle_and_the_same_for_a_seed(default_scene):
    """Every Super Graph node and a sample of edges of a tiny roadmap with task nodes, by the oracle (full meshes, its
    own resolution); built twice with one seed, the same arrays."""
    roadmap = build_roadmap(default_scene, TINY, seed=4)[0]
    again = build_roadmap(default_scene, TINY, seed=4)[0]
    for field in dataclasses.fields(roadmap):
        a, b = getattr(roadmap, field.name), getattr(again, field.name)
        assert (np.array_equal(a, b) if isinstance(a, np.ndarray) else a == b), field.name
    oracle = Oracle(default_scene)
    assert not [hit for q in roadmap.node_q for hit in oracle.robot_collisions(q)]
    rng = np.random.default_rng(0)
    for u, v in roadmap.edges[rng.choice(len(roadmap.edges), min(30, len(roadmap.edges)), replace=False)]:
        qa, qb = roadmap.node_q[u], roadmap.node_q[v]
        n = max(2, math.ceil(np.abs(qb - qa).max() / 0.01) + 1)
        assert not [hit for t in np.linspace(0.0, 1.0, n) for hit in oracle.robot_collisions(qa + t * (qb - qa))]
