"""Building the offline roadmap: both Vis-PRMs, then the Super Graph's nodes and edges, on a process pool.

The collision model is built once and inherited by forked workers; each worker makes its own
checker (scratch data is per process). Work is split into ordered chunks and results are put back
in order, so the roadmap depends on the seed only, never on the number of workers.
"""
from __future__ import annotations

import time
from concurrent.futures import Executor

import numpy as np
import pinocchio as pin

from planner.collision.checker import CollisionModel, build_collision_model
from planner.collision.pairs import CollisionParams
from planner.collision.segments import SegmentChecker
from planner.core.forked import available_cpus, executor
from planner.core.steps import Progress, no_progress
from planner.model.robot import Robot
from planner.model.task import Scene
from planner.roadmap import super_graph as sg
from planner.roadmap.decomposition import Decomposition, decompose, pair_subsets
from planner.roadmap.result import Roadmap, RoadmapParams
from planner.roadmap.task_prm import task_prm
from planner.roadmap.task_sites import task_sites
from planner.roadmap.vis_prm import Elementary, vis_prm

_WORKER: dict = {}


def roadmap_collision_model(scene: Scene, params: RoadmapParams) -> tuple[CollisionModel, Decomposition]:
    """The scene's collision model with the roadmap's paddings and pair subsets."""
    dec = decompose(scene.robot)
    cm = build_collision_model(scene.robot, scene.environment,
                               CollisionParams(env_padding=params.env_padding, self_padding=params.self_padding))
    return cm.with_subsets(pair_subsets(cm, dec)), dec


def segment_checker(cm: CollisionModel, params: RoadmapParams) -> SegmentChecker:
    """The local planner at the resolution the parameters state."""
    return SegmentChecker(cm, params.env_clearance)


def resolution(params: RoadmapParams) -> dict:
    """The stated collision-checking resolution and what it guarantees."""
    return {
        "bound": "largest displacement of any robot point, relative to what it may hit, between two checks",
        "obstacle_step_m": round(2 * (params.env_padding - params.env_clearance), 6),
        "robot_step_m": round(2 * params.self_padding, 6),
        "env_padding_m": params.env_padding,
        "self_padding_m": params.self_padding,
        "env_clearance_m": params.env_clearance,
        "self_clearance_m": 0.0,
    }


def _init_worker(cm: CollisionModel, params: RoadmapParams) -> None:
    _WORKER["seg"] = segment_checker(cm, params)


def _segments_job(qa: np.ndarray, qb: np.ndarray, subsets: list[str]) -> tuple[np.ndarray, int]:
    seg: SegmentChecker = _WORKER["seg"]
    before = seg.checks
    ok = np.array([seg.segment_free(a, b, s) for a, b, s in zip(qa, qb, subsets)], dtype=bool)
    return ok, seg.checks - before


def _vis_prm_job(dec: Decomposition, arm: str, seed: int, params: RoadmapParams, sites: np.ndarray) -> tuple[Elementary, int]:
    """One arm's elementary roadmap: Vis-PRM, then the nodes around and between the task's sites (task_prm.py)."""
    seg: SegmentChecker = _WORKER["seg"]
    before = seg.checks
    robot = seg.cm.robot
    idx = dec.subsystem(arm)
    rng = np.random.default_rng(seed)
    lower, upper = robot.lower[idx], robot.upper[idx]
    elem = vis_prm(seg, f"sub/{arm}", dec.q_hold, idx, lower, upper, rng, params.radius, params.nodes, params.max_failures)
    if params.task_nodes:
        elem = task_prm(seg, f"sub/{arm}", dec.q_hold, idx, lower, upper, elem, sites, rng, params.task_nodes, params.task_spread,
                        params.task_edge, params.task_neighbours, params.radius, params.bridge_attempts)
    return elem, seg.checks - before


def _check_all(pool: Executor, qa: np.ndarray, qb: np.ndarray, subsets: list[str], workers: int,
               progress: Progress, message: str) -> tuple[np.ndarray, int]:
    """Check segments qa[i] -> qb[i] (a configuration when qa[i] == qb[i]) in ordered chunks; the progress message
    counts the candidates checked of all and those kept so far."""
    if not len(qa):
        return np.zeros(0, dtype=bool), 0
    bounds = np.linspace(0, len(qa), min(len(qa), 16 * workers) + 1).astype(int)
    futures = [pool.submit(_segments_job, qa[a:b], qb[a:b], subsets[a:b]) for a, b in zip(bounds[:-1], bounds[1:])]
    kept = 0
    for k, f in enumerate(futures):
        kept += int(f.result()[0].sum())
        progress((k + 1) / len(futures), f"{message}: {bounds[k + 1]:,} of {len(qa):,} candidates checked, {kept:,} kept")
    results = [f.result() for f in futures]
    return np.concatenate([r[0] for r in results]), sum(r[1] for r in results)


def build_roadmap(scene: Scene, params: RoadmapParams, seed: int, progress: Progress = no_progress) -> tuple[Roadmap, dict[str, float]]:
    """(both elementary roadmaps and their Super Graph (deterministic in `seed`), the seconds of each stage)."""
    cm, dec = roadmap_collision_model(scene, params)
    arms = dec.arms
    seeds = np.random.SeedSequence(seed).generate_state(len(arms) + 1, dtype=np.uint64)
    timings, checks = {}, {}
    sites = {arm: np.zeros((0, len(dec.subsystem(arm)))) for arm in arms}
    if params.task_nodes:
        t = time.perf_counter()
        progress(0.0, "the task's sites (IK)")
        sites = task_sites(scene, dec, build_collision_model(scene.robot, scene.environment).checker(), params.site_starts,
                           np.random.default_rng(int(seeds[-1])))
        timings["sites"], checks["sites"] = time.perf_counter() - t, 0
    workers = available_cpus()
    with executor(workers, _init_worker, (cm, params)) as pool:
        t = time.perf_counter()
        progress(0.05, "elementary roadmaps (Vis-PRM, then the task's sites)")
        jobs = [pool.submit(_vis_prm_job, dec, arm, int(s), params, sites[arm]) for arm, s in zip(arms, seeds)]
        elems = [j.result() for j in jobs]
        timings["vis_prm"] = time.perf_counter() - t
        checks["vis_prm"] = sum(c for _, c in elems)
        e0, e1 = (e for e, _ in elems)
        q0, q1 = (dec.compose({arm: e.nodes[:, len(dec.common):]}, e.nodes[:, : len(dec.common)]) for arm, e in zip(arms, (e0, e1)))

        t = time.perf_counter()
        pairs, source = sg.node_candidates(len(e0.nodes), len(e1.nodes))
        common = np.where(source[:, None] == 0, e0.nodes[pairs[:, 0], : len(dec.common)], e1.nodes[pairs[:, 1], : len(dec.common)])
        cand_q = dec.compose({arms[0]: e0.nodes[pairs[:, 0], len(dec.common):], arms[1]: e1.nodes[pairs[:, 1], len(dec.common):]},
                             common)
        ok, n_checks = _check_all(pool, cand_q, cand_q, sg.node_subsets(source, arms), workers,
                                  lambda f, m: progress(0.2 + 0.05 * f, m), "Super Graph nodes")
        node_elem, node_common, node_q = pairs[ok], source[ok], cand_q[ok]
        timings["sg_nodes"] = time.perf_counter() - t
        checks["sg_nodes"] = n_checks

        t = time.perf_counter()
        cand, subsets = sg.edge_candidates(node_elem, node_common, e0.edges, e1.edges, arms, params.mixed_edges,
                                         params.one_arm_edges, params.both_arm_edges, params.other_arm_edges)
        switch = np.all(node_elem[cand[:, 0]] == node_elem[cand[:, 1]], axis=1)
        common = dec.common
        near = np.linalg.norm(node_q[cand[:, 0]][:, common] - node_q[cand[:, 1]][:, common], axis=1) <= params.switch_length
        kept = ~switch | near
        cand, subsets = cand[kept], [sub for sub, k in zip(subsets, kept) if k]
        if params.tree:
            seg = segment_checker(cm, params)
            uf = sg.UnionFind(len(node_q))
            keep = np.zeros(len(cand), dtype=bool)
            for k, ((u, v), s) in enumerate(zip(cand, subsets)):
                if uf.find(u) != uf.find(v) and seg.segment_free(node_q[u], node_q[v], s, ends=False):
                    keep[k] = uf.union(u, v)
                if k % 200 == 0:
                    progress(0.25 + 0.75 * k / len(cand), f"Super Graph edges (tree): {k:,} of {len(cand):,} candidates "
                             f"checked, {int(keep.sum()):,} kept")
            n_checks = seg.checks
        else:
            keep, n_checks = _check_all(pool, node_q[cand[:, 0]], node_q[cand[:, 1]], subsets, workers,
                                        lambda f, m: progress(0.25 + 0.75 * f, m), "Super Graph edges")
        timings["sg_edges"] = time.perf_counter() - t
        checks["sg_edges"] = n_checks
    edges = cand[keep]
    robot = scene.robot
    elem_q = np.concatenate([q0, q1])
    n0 = len(q0)
    return Roadmap(
        arms=list(arms),
        resolution=resolution(params),
        checks=checks,
        candidates={"nodes": len(cand_q), "edges": len(cand)},
        vis_prm_samples={arm: e.samples for arm, e in zip(arms, (e0, e1))},
        elem_q=elem_q,
        elem_arm=np.repeat(np.array([0, 1], dtype=np.int8), [n0, len(q1)]),
        elem_guard=np.concatenate([e0.guard, e1.guard]),
        elem_edges=np.concatenate([e0.edges, e1.edges + n0]),
        node_q=node_q,
        node_elem=node_elem + np.array([0, n0]),
        node_common=node_common.astype(np.int8),
        node_component=sg.components(len(node_q), edges),
        wrists=wrist_positions(robot, node_q),
        edges=edges,
        edge_length=np.linalg.norm(node_q[edges[:, 0]] - node_q[edges[:, 1]], axis=1),
        edge_valid=np.ones(len(edges), dtype=bool),
    ), timings


def wrist_positions(robot: Robot, q: np.ndarray) -> np.ndarray:
    """(n, arms, 3) world positions of each arm's wrist frame (its hand's mount frame) at each configuration."""
    data = robot.model.createData()
    fids = [robot.frame_id(robot.wrist_frame(arm)) for arm in robot.spec.arm_names]
    out = np.empty((len(q), len(fids), 3))
    for i, qi in enumerate(q):
        pin.framesForwardKinematics(robot.model, data, qi)
        out[i] = [data.oMf[f].translation for f in fids]
    return out
