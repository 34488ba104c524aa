"""Grasp frames dropped before any finger search, in one pass over all frames, each by the first test it fails.

In order: the palm inside the object (a body shape's centre behind the tangent plane of its nearest
object point and farther from it than the points' spacing: a surface's far side lies nearer than
that), the hand body hitting the object (certain hits by the balls inside the body's shapes, coal's
exact test for the rest), the thumb's workspace holding no contact candidate (no thumb contact can
be found), and fewer than `MIN_CONTACTS` fingers' workspaces holding one (no grasp can be found).
The candidates found on the way are what the finger search starts from.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from planner.grasping.candidates import Candidates
from planner.grasping.screens import bounding

if TYPE_CHECKING:
    from planner.grasping.search import GraspSearch

MIN_CONTACTS = 3
REJECTIONS = ("palm_inside", "body_collides", "thumb_misses", "unreachable")


def palm_inside(search: GraspSearch, H: np.ndarray) -> np.ndarray:
    """(n,) True where a body shape's centre lies inside the object, deeper than the point spacing."""
    inside = np.zeros(len(H), bool)
    for shape in search.hand.body:
        world = H @ shape.placement
        centres = world[:, :3, :3] @ bounding(shape.geometry, np.eye(4))[0] + world[:, :3, 3]
        d, i = search.obj.tree.query(centres)
        behind = np.einsum("ij,ij->i", centres - search.obj.points[i], search.obj.normals[i]) < 0
        inside |= behind & (d > search.obj.step)
    return inside


def body_hits(search: GraspSearch, H: np.ndarray) -> np.ndarray:
    """(n,) True where a body shape hits the object (screened by its inside balls, then coal)."""
    hit = np.zeros(len(H), bool)
    for j, shape in enumerate(search.hand.body):
        world = (H @ shape.placement)[:, None]
        hit |= search.screen.hits(world, [search.body_balls[j]])
        for k in np.flatnonzero(~hit):
            hit[k] = search.test.hits_object(shape.geometry, world[k, 0])
    return hit


def rejected(search: GraspSearch, H: np.ndarray) -> tuple[np.ndarray, list[Candidates]]:
    """Per frame (n,) the rejection it meets ('' for none), and per finger (spec order) the kept frames' candidates."""
    reason = np.full(len(H), "", object)
    reason[palm_inside(search, H)] = "palm_inside"
    kept = np.flatnonzero(reason == "")
    reason[kept[body_hits(search, H[kept])]] = "body_collides"
    kept = np.flatnonzero(reason == "")
    thumb = search.hand.thumb_first[0]
    thumbs = search.finders[thumb](H[kept])
    reason[kept[thumbs.counts(len(kept)) == 0]] = "thumb_misses"
    found = {thumb: thumbs.renumbered(kept)}
    kept = np.flatnonzero(reason == "")
    reaching = np.ones(len(H), int)
    for fi in search.hand.thumb_first[1:]:
        found[fi] = search.finders[fi](H[kept]).renumbered(kept)
        reaching += found[fi].counts(len(H)) > 0
    reason[kept[reaching[kept] < MIN_CONTACTS]] = "unreachable"
    return reason, [found[fi] for fi in range(len(search.finders))]
