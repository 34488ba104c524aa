"""The exchange position (paper V-C, figure 6): a 3-D grid node minimising the palms' travel.

Cost of a node e: ig + ge + ef for the picking palm (initial -> grasp -> exchange -> final) plus
ie + ep + pf for the placing palm (initial -> exchange -> place -> final). The terms that do not
involve e are constant, but are kept so the cost is the full distance the paper minimises.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from planner.core.errors import RegraspError

MAX_GRID_NODES = 4_000_000  # exchange grid nodes a run may hold: about 100 MB of positions, a few times that at the peak


@dataclass(frozen=True)
class PalmWaypoints:
    """Palm positions (world, m) of the picking arm (initial, grasp, final) and placing arm (initial, place, final)."""

    pick_initial: np.ndarray
    pick_grasp: np.ndarray
    pick_final: np.ndarray
    place_initial: np.ndarray
    place_place: np.ndarray
    place_final: np.ndarray


def grid_shape(lower: np.ndarray, upper: np.ndarray, step: float) -> tuple[int, int, int]:
    """Nodes per axis of the grid covering [lower, upper] at `step` (what np.arange below makes)."""
    x, y, z = (int(np.floor((hi - lo + 1e-9) / step)) + 1 for lo, hi in zip(lower, upper))
    return x, y, z


def grid_nodes(lower: np.ndarray, upper: np.ndarray, step: float) -> np.ndarray:
    """Nodes of a regular grid covering the box [lower, upper] (x fastest, then y, then z); a grid of more than
    MAX_GRID_NODES is refused before it is made, naming the smallest step that fits (the box depends on the robot)."""
    count = math.prod(grid_shape(lower, upper, step))
    if count > MAX_GRID_NODES:
        fits = step
        while math.prod(grid_shape(lower, upper, fits)) > MAX_GRID_NODES:
            fits *= 1.05
        size = " x ".join(f"{hi - lo:.2f}" for lo, hi in zip(lower, upper))
        raise RegraspError(f"step 'exchange': parameter step {step:g} m makes a grid of {count:,} nodes over the {size} m box both "
                           f"hands reach, more than the {MAX_GRID_NODES:,} a run may hold: set exchange.step to {fits:.3g} m or more")
    axes = [np.arange(lo, hi + 1e-9, step) for lo, hi in zip(lower, upper)]
    zz, yy, xx = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    return np.c_[xx.ravel(), yy.ravel(), zz.ravel()]


def exchange_costs(nodes: np.ndarray, w: PalmWaypoints) -> np.ndarray:
    """ig + ge + ef + ie + ep + pf for every node (vectorised)."""
    d = lambda a, b: np.linalg.norm(np.asarray(a) - np.asarray(b), axis=-1)
    fixed = d(w.pick_initial, w.pick_grasp) + d(w.place_place, w.place_final)
    return fixed + d(w.pick_grasp, nodes) + d(nodes, w.pick_final) + d(w.place_initial, nodes) + d(nodes, w.place_place)


def best_nodes(costs: np.ndarray, free: np.ndarray, keep: int) -> np.ndarray:
    """Indices of the `keep` cheapest collision-free nodes, cheapest first (ties by index: deterministic)."""
    candidates = np.flatnonzero(free)
    order = np.lexsort((candidates, costs[candidates]))
    return candidates[order[:keep]]
