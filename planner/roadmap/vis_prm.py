"""Visibility-PRM (Siméon, Laumond, Nissoux 2000) for one sub-system: a compact roadmap of guards and connectors.

A free sample that sees no guard becomes a guard (a new component); one that sees guards of two or
more components becomes a connector linked to one guard of each, merging them; any other sample is
dropped. A guard's visibility is limited to `radius` (joint-space distance over the sub-system's
joints, as a maximum local-path length): without it a handful of guards sees the whole space, and
the radius sets how many nodes cover it. Construction stops at `max_nodes` nodes or after
`max_failures` dropped samples in a row. Guards of a component are tried nearest first.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.collision.segments import SegmentChecker
from planner.core.steps import Progress, no_progress


@dataclass(frozen=True)
class Elementary:
    """One sub-system's roadmap: node values of the sub-system's joints, edges, and which nodes are guards."""

    nodes: np.ndarray  # (n, k) values of the sub-system's configuration indices
    edges: np.ndarray  # (m, 2) int, node indices
    guard: np.ndarray  # (n,) bool
    samples: int


def vis_prm(seg: SegmentChecker, subset: str, base: np.ndarray, idx: np.ndarray, lower: np.ndarray, upper: np.ndarray,
            rng: np.random.Generator, radius: float, max_nodes: int, max_failures: int,
            progress: Progress = no_progress) -> Elementary:
    """Build the roadmap of the joints `idx` (others held at `base`) against the pair subset `subset`."""
    nodes: list[np.ndarray] = []
    guard: list[bool] = []
    edges: list[tuple[int, int]] = []
    components: list[list[int]] = []  # guard node ids per component
    failures = samples = 0
    q = base.copy()
    while len(nodes) < max_nodes and failures < max_failures:
        samples += 1
        q[idx] = rng.uniform(lower, upper)
        if not seg.free(q, subset):
            continue
        seen: list[tuple[int, int]] = []  # (component, guard)
        for c, comp in enumerate(components):
            dist = np.linalg.norm(np.array([nodes[g] for g in comp]) - q[idx], axis=1)
            for k in np.argsort(dist):
                if dist[k] > radius:
                    break
                if seg.segment_free(q, full_config(base, idx, nodes[comp[k]]), subset, ends=False):
                    seen.append((c, comp[k]))
                    break
        if len(seen) == 1:
            failures += 1
            continue
        failures = 0
        n = len(nodes)
        nodes.append(q[idx].copy())
        guard.append(not seen)
        if not seen:
            components.append([n])
        else:
            edges += [(n, g) for _, g in seen]
            merged = [g for c, _ in seen for g in components[c]]
            components = [comp for c, comp in enumerate(components) if c not in {c for c, _ in seen}] + [merged]
        progress(len(nodes) / max_nodes, f"{len(nodes)} nodes, {len(components)} components, {samples} samples")
    return Elementary(np.array(nodes).reshape(-1, len(idx)), np.array(edges, dtype=np.int64).reshape(-1, 2),
                      np.array(guard, dtype=bool), samples)


def full_config(base: np.ndarray, idx: np.ndarray, values: np.ndarray) -> np.ndarray:
    """`base` with the joints `idx` at `values`."""
    q = base.copy()
    q[idx] = values
    return q
