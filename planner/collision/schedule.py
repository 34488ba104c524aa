"""The order and the subsets of evenly spaced configurations a segment's or a curve's check visits (segments.py):
bisection (van der Corput) order, so that a colliding motion fails early; levels of pairs checked every 2^j-th
configuration, coarsest first; the configurations that bound some spans; coarse paddings first, fine ones only beside
what fails them.
"""
from __future__ import annotations

import functools
from collections.abc import Callable

import numpy as np

from planner.core.results import frozen


@functools.lru_cache(maxsize=4096)
def level_order(n: int, top: int) -> tuple[tuple[int, np.ndarray], ...]:
    """The indices 0..n-1 by level, coarsest first: level `top` holds 0, n-1 and the multiples of 2^top, level j < top
    the odd multiples of 2^j; within a level in van der Corput order (read-only, computed once per n and top)."""
    order = bisection_indices(n)
    odd = order & -order  # the largest power of two dividing each index (0 for index 0)
    level = np.where((order == 0) | (order == n - 1), top, np.minimum(np.log2(np.maximum(odd, 1)).astype(int), top))
    return tuple((j, frozen(order[level == j])) for j in range(top, -1, -1) if np.any(level == j))


@functools.lru_cache(maxsize=4096)
def bisection_indices(n: int) -> np.ndarray:
    """The indices 0..n-1 in van der Corput order (read-only, computed once per n)."""
    return frozen((van_der_corput(n) * (n - 1)).round().astype(int))


@functools.lru_cache(maxsize=4096)
def van_der_corput(n: int) -> np.ndarray:
    """The n parameters 0, 1/(n-1), ..., 1 in bisection order: ends first, then midpoints, coarse to fine (read-only:
    computed once per n, as every segment of n checks asks for the same order)."""
    if n <= 1:
        return frozen(np.zeros(max(n, 0)))
    order = [np.array([0, n - 1])]
    a, b = np.array([0]), np.array([n - 1])
    while len(a):  # level by level: each interval's midpoint, then its halves in order
        a, b = a[b - a > 1], b[b - a > 1]
        m = (a + b) // 2
        order.append(m)
        a, b = np.stack([a, m], axis=1).ravel(), np.stack([m, b], axis=1).ravel()
    return frozen(np.concatenate(order).astype(float) / (n - 1))


def bounding(indices: np.ndarray, windows: np.ndarray, n: int, step: int = 1) -> np.ndarray:
    """The indices (of n configurations) from the last multiple of `step` at or before a window (parameters 0..1) to the
    first at or after it (or the last configuration), in their order."""
    at = windows * (n - 1) / step
    lo = np.floor(at[:, 0] - 1e-9) * step
    hi = np.minimum(np.ceil(at[:, 1] + 1e-9) * step, n - 1)
    return indices[np.any((indices[:, None] >= lo) & (indices[:, None] <= hi), axis=1)]


def coarse_first(n: int, k: int, hits: Callable[[float, bool], bool], ends: bool = True,
                 screen: bool = False, windows: np.ndarray | None = None) -> float | None:
    """Where a segment checked at n evenly spaced configurations (parameters 0..1) fails, checked coarse first (see the
    module); None when it passes. `hits(s, coarse)`: whether the check at s fails, at the coarse paddings or at the
    paddings. Every k-th of (at least) n configurations is checked coarse (see two_level). `ends=False`: both ends are
    known to pass at the paddings; `screen`, `windows`: see two_level."""
    m = -(-(n - 1) // k)  # coarse intervals; m * k >= n - 1 fine ones
    return two_level(m + 1, m * k + 1, hits, ends, screen=screen, windows=windows)


def two_level(n: int, m: int, hits: Callable[[float, bool], bool], ends: bool = True,
              between: Callable[[float], bool] | None = None, screen: bool = False,
              windows: np.ndarray | None = None) -> float | None:
    """Where a segment fails, checked at n evenly spaced configurations at coarse paddings and, only within the
    intervals next to one that fails there, at the m (> n) evenly spaced configurations of its fine paddings; None
    when it passes. `hits(s, coarse)`: whether the check at parameter s fails at the coarse or the fine paddings. The
    coarse ones go in van der Corput order, one that fails there at once at the fine paddings too (a collision is found
    early). Each interval between two checked configurations is then as short as the paddings both its ends passed at
    need. `ends=False`: both ends are known to pass at the fine paddings. `between(s)`: whether a configuration strictly
    inside such an interval fails (default: hits(s, False)): there only the pairs padded less finely than coarsely need a
    test, as every other pair passed at its padding at the coarse configurations. `screen`: the coarse configurations
    only (None where they pass: no guarantee); `windows` ((k, 2) parameters): only what bounds them, the coarse
    configurations again (their answers decide which intervals the fine ones fill)."""
    between = between or (lambda s: hits(s, False))
    clear = np.ones(n, dtype=bool)  # outside the windows: nothing to fill
    order = bisection_indices(n)
    for j in order if windows is None else bounding(order, windows, n):
        s = j / (n - 1)
        clear[j] = not hits(s, True)
        if not clear[j] and (ends or 0 < j < n - 1) and hits(s, False):
            return s
    if screen:
        return None
    for j in np.flatnonzero(~(clear[:-1] & clear[1:])):
        for i in range(j * (m - 1) // (n - 1) + 1, -(-(j + 1) * (m - 1) // (n - 1))):  # strictly inside
            if between(i / (m - 1)):
                return i / (m - 1)
    return None
