"""An elementary roadmap made dense where the task's queries land, then joined into one piece.

Vis-PRM (vis_prm.py) covers a sub-system's space with few nodes and long edges: a query end lies far from all of them
and the edge joining it is long, checked online over every pair. Here nodes are added around the task's sites
(task_sites.py) and along the straight lines between two of them (a site, or a point between two, plus Gaussian noise
of `spread` rad per joint), each joined to its `neighbours` nearest nodes no farther than `edge` rad: short edges,
which online a query end joins cheaply and a path follows closely. Last, every component but the largest is bridged
to the rest by its nearest valid pair of nodes no farther than `bridge` rad (`attempts` pairs tried, nearest first),
so that the Super Graph's components are the elementary ones' product and few; a node still apart is dropped.
"""
from __future__ import annotations

import numpy as np

from planner.collision.segments import SegmentChecker
from planner.roadmap.super_graph import UnionFind
from planner.roadmap.vis_prm import Elementary, full_config


def task_prm(seg: SegmentChecker, subset: str, base: np.ndarray, idx: np.ndarray, lower: np.ndarray, upper: np.ndarray,
             elem: Elementary, sites: np.ndarray, rng: np.random.Generator, nodes: int, spread: float, edge: float,
             neighbours: int, bridge: float, attempts: int) -> Elementary:
    """`elem` with `nodes` more nodes around and between `sites` ((k, len(idx)) values of the joints `idx`; others held
    at `base`) checked against the pair subset `subset`, and its components bridged (see the module)."""
    q = [np.asarray(v, float) for v in elem.nodes]
    edges = [tuple(map(int, e)) for e in elem.edges]
    guard = list(map(bool, elem.guard))
    samples = elem.samples
    added = tries = 0
    while added < nodes and len(sites) and tries < 50 * max(nodes, 1):
        tries += 1
        if tries <= len(sites):  # the sites themselves first
            x = sites[tries - 1].copy()
        else:
            a, b = sites[rng.integers(len(sites))], sites[rng.integers(len(sites))]
            x = np.clip(a + rng.uniform() * (b - a) + rng.normal(0.0, spread, len(idx)), lower, upper)
        samples += 1
        full = full_config(base, idx, x)
        if not seg.free(full, subset):
            continue
        n = len(q)
        if n:
            dist = np.linalg.norm(np.array(q) - x, axis=1)
            joined = 0
            for k in np.argsort(dist, kind="stable"):
                if joined >= neighbours or dist[k] > edge:
                    break
                if seg.segment_free(full, full_config(base, idx, q[k]), subset, ends=False):
                    edges.append((int(k), n))
                    joined += 1
        q.append(x)
        guard.append(False)
        added += 1
    nodes_q = np.array(q).reshape(-1, len(idx))
    edges += _bridges(seg, subset, base, idx, nodes_q, edges, bridge, attempts)
    return _largest(Elementary(nodes_q, np.array(edges, dtype=np.int64).reshape(-1, 2), np.array(guard, dtype=bool), samples))


def _largest(elem: Elementary) -> Elementary:
    """The roadmap's largest component alone (nodes in their order, edges renumbered): a node no bridge joins is where
    no path of the graph goes, and in the Super Graph its product with every node of the other arm would be too."""
    uf = UnionFind(len(elem.nodes))
    for u, v in elem.edges:
        uf.union(int(u), int(v))
    roots = np.array([uf.find(i) for i in range(len(elem.nodes))], dtype=np.int64)
    if not len(roots):
        return elem
    keep = roots == np.bincount(roots).argmax()
    renumber = np.cumsum(keep) - 1
    edges = elem.edges[keep[elem.edges[:, 0]] & keep[elem.edges[:, 1]]]
    return Elementary(elem.nodes[keep], renumber[edges].reshape(-1, 2), elem.guard[keep], elem.samples)


def _bridges(seg: SegmentChecker, subset: str, base: np.ndarray, idx: np.ndarray, q: np.ndarray, edges: list[tuple[int, int]],
             bridge: float, attempts: int) -> list[tuple[int, int]]:
    """Edges joining the smaller components to the rest, smallest component first, each by the first valid of its
    `attempts` nearest pairs of nodes no farther than `bridge` apart."""
    uf = UnionFind(len(q))
    for u, v in edges:
        uf.union(u, v)
    out: list[tuple[int, int]] = []
    failed: set[tuple[int, int]] = set()  # pairs found blocked (a component that cannot join is tried again after others did)
    while True:
        roots = np.array([uf.find(i) for i in range(len(q))])
        labels, sizes = np.unique(roots, return_counts=True)
        if len(labels) < 2:
            return out
        joined = False
        for label in labels[np.argsort(sizes, kind="stable")][:-1]:
            inside, outside = np.flatnonzero(roots == label), np.flatnonzero(roots != label)
            d = np.linalg.norm(q[inside][:, None] - q[outside][None], axis=2)
            for flat in np.argsort(d, axis=None, kind="stable")[:attempts]:
                i, j = np.unravel_index(flat, d.shape)
                if d[i, j] > bridge:
                    break
                u, v = int(inside[i]), int(outside[j])
                if (u, v) in failed:
                    continue
                if seg.segment_free(full_config(base, idx, q[u]), full_config(base, idx, q[v]), subset, ends=False):
                    out.append((u, v))
                    uf.union(u, v)
                    joined = True
                    break
                failed.add((u, v))
            if joined:
                break
        if not joined:
            return out
