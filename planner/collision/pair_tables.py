"""Pair tables as pinocchio sets pair flags and paddings in one call, and the tables of a subset whose object pairs are
screened by the object's convex hull (see CollisionChecker.in_collision)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from planner.collision.checker import CollisionModel


def pair_table(cm: CollisionModel, per_pair: np.ndarray) -> np.ndarray:
    """(n_geometries, n_geometries) symmetric table of a per-pair value, as pinocchio sets pair flags and margins in one
    call (a Python loop over thousands of pairs cost more than checking a short motion)."""
    n = len(cm.geometry.geometryObjects)
    out = np.zeros(n * n, dtype=per_pair.dtype)  # flat indices: numpy's two-index assignment costs four times more
    first, second = cm.ends[:, 0] * n, cm.ends[:, 1]
    out[first + second] = per_pair
    out[second * n + cm.ends[:, 0]] = per_pair
    return out.reshape(n, n)


def active_table(cm: CollisionModel, subset: str | np.ndarray) -> np.ndarray:
    """The pair table of a subset (a name, or pair indices) as pinocchio activates pairs."""
    active = np.zeros(len(cm.ends), dtype=bool)
    active[cm.subsets[subset] if isinstance(subset, str) else subset] = True
    return pair_table(cm, active)


@dataclass(frozen=True)
class Screen:
    """A subset checked first with screening pairs in place of their twins (see CollisionChecker.in_collision)."""

    screened: np.ndarray  # the pair table with the screening pairs active instead of their twins
    exact: np.ndarray  # the subset's own pair table
    screening: np.ndarray  # (n_pairs,) bool: the screening pairs


def screen_of(cm: CollisionModel, subset: str | np.ndarray) -> Screen | None:
    """The screen of a subset (a name, or pair indices), when it has pairs with a screening twin."""
    if cm.twins is None:
        return None
    pairs = cm.subsets[subset] if isinstance(subset, str) else subset
    stand_in = np.full(len(cm.ends), -1)
    screening = cm.twins >= 0
    stand_in[cm.twins[screening]] = np.flatnonzero(screening)
    if not np.any(stand_in[pairs] >= 0):
        return None
    screened = np.where(stand_in[pairs] >= 0, stand_in[pairs], pairs)
    return Screen(active_table(cm, screened), active_table(cm, pairs), screening)
