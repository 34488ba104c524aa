"""The Super Graph (paper V-A; Gharbi, Cortés, Siméon): the composition of the two elementary roadmaps.

Nodes: every pair (x_0, x_1) of elementary nodes gives two candidates, the common part taken from
x_0 or from x_1. Each x_a was checked for its sub-system (common part + arm a, self and obstacles),
so the candidate whose common part comes from x_a only needs the other arm against everything else
('cross/<other arm>'). Edges: only between nodes whose elementary nodes are joined by an edge in
both roadmaps. With the same source s on both ends, the sub-system of s moves exactly along its
elementary edge, so only 'cross/<other arm>' is checked; when the source switches (optional: the
paper's filter allows it, but it doubles the edge stage), the common part moves along neither
elementary edge and every moving pair not inside one arm ('mixed') is checked (intra-arm pairs
depend on that arm's joints only, which follow their elementary edge). The two nodes of one
elementary pair are joined by a 'switch' edge (arms still, the common part moves; 'mixed' again),
which links the halves of the graph with either source at a fraction of the cost. Edges moving one arm at a time
make each half the product of the elementary roadmaps (its components theirs) at a small part of the cost of
moving both arms at once, whose edge count is the product of the elementary edge counts.
"""
from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components


def node_candidates(n0: int, n1: int) -> tuple[np.ndarray, np.ndarray]:
    """(elementary node pairs (c, 2), common-part source (c,)) for every candidate SG node."""
    i, j = np.meshgrid(np.arange(n0), np.arange(n1), indexing="ij")
    pairs = np.stack([i.ravel(), j.ravel()], axis=1)
    return np.concatenate([pairs, pairs]), np.repeat(np.array([0, 1], dtype=np.int8), len(pairs))


def node_subsets(source: np.ndarray, arms: tuple[str, str]) -> list[str]:
    """The pair subset checking each candidate node: the arm whose common part changed, against the rest."""
    return [f"cross/{arms[1 - s]}" for s in source]


def edge_candidates(node_elem: np.ndarray, node_source: np.ndarray, edges0: np.ndarray, edges1: np.ndarray,
                    arms: tuple[str, str], mixed: bool, one_arm: bool = False, both: bool = True,
                    other_arm: bool = False) -> tuple[np.ndarray, list[str]]:
    """(c, 2) SG node pairs to test, in a deterministic order, and the pair subset checking each.

    With `both`, edges along an elementary edge in both roadmaps with the same common-part source (with `mixed`, also
    those whose source switches); with `one_arm`, those along an elementary edge of the arm whose common part the nodes
    take, the other arm still; with `other_arm`, those along an elementary edge of the other arm, the common part and
    the first arm still (that arm against everything else is what changed: its own pairs moved as in its roadmap); and
    'switch' edges between the two nodes of one elementary pair (only the common part moves, from one source to the
    other).
    """
    index = {(int(a), int(b), int(s)): k for k, (a, b, s) in enumerate(zip(node_elem[:, 0], node_elem[:, 1], node_source))}
    out, subsets = [], []
    if both:
        for a, b in edges0:
            for c, d in edges1:
                for (x0, x1), (y0, y1) in (((a, c), (b, d)), ((a, d), (b, c))):
                    for s, t in ((0, 0), (1, 1), (0, 1), (1, 0)) if mixed else ((0, 0), (1, 1)):
                        u, v = index.get((x0, x1, s)), index.get((y0, y1, t))
                        if u is not None and v is not None:
                            out.append((u, v))
                            subsets.append(f"cross/{arms[1 - s]}" if s == t else "mixed")
    for s in (0, 1):  # the half of the graph whose nodes take the common part from arm s
        for m, elementary in ((0, edges0), (1, edges1)):  # the arm that moves
            if not (one_arm if m == s else other_arm):
                continue

            def key(moving: int, still: int, m: int = m, s: int = s) -> tuple[int, int, int]:
                return (moving, still, s) if m == 0 else (still, moving, s)

            for a, b in elementary:
                for still in np.unique(node_elem[:, 1 - m]).tolist():
                    u, v = index.get(key(a, still)), index.get(key(b, still))
                    if u is not None and v is not None:
                        out.append((u, v))
                        subsets.append(f"cross/{arms[1 - m]}" if m == s else f"cross/{arms[m]}")
    for (x0, x1, s), u in index.items():
        v = index.get((x0, x1, 1))
        if s == 0 and v is not None:
            out.append((u, v))
            subsets.append("mixed")
    return np.array(out, dtype=np.int64).reshape(-1, 2), subsets


def components(n: int, edges: np.ndarray) -> np.ndarray:
    """(n,) connected-component label of each node."""
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    return connected_components(graph, directed=False)[1].astype(np.int64)


class UnionFind:
    """Disjoint sets over node ids, for the tree variant (connect only different components)."""

    def __init__(self, n: int):
        self.parent = np.arange(n)

    def find(self, a: int) -> int:
        root = a
        while self.parent[root] != root:
            root = self.parent[root]
        while self.parent[a] != root:
            self.parent[a], a = root, self.parent[a]
        return int(root)

    def union(self, a: int, b: int) -> bool:
        """Join the sets of a and b; False if they were already one."""
        ra, rb = self.find(a), self.find(b)
        if ra == rb:
            return False
        self.parent[max(ra, rb)] = min(ra, rb)
        return True
