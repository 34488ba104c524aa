"""Grasp frames dropped before any finger search, in one pass over all frames, each by the first test it fails.

In order: the palm inside the object (a body shape's centre inside the surface by the winding number,
asked only where the centre is behind the tangent plane of its nearest object point), the hand body
hitting the object (certain hits by object points inside the body's shapes, coal's exact test for the
rest), the thumb's workspace holding no contact candidate (no thumb contact can be found), and fewer
than `MIN_CONTACTS` fingers' workspaces holding one (no grasp can be found). The candidates found on
the way are what the finger search starts from.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from planner.collision.object_screens import bounding
from planner.collision.shapes import transform3s
from planner.grasping.candidates import Candidates

if TYPE_CHECKING:
    from planner.grasping.search import GraspSearch

MIN_CONTACTS = 3
REJECTIONS = ("palm_inside", "body_collides", "thumb_misses", "unreachable")
WINDING_BLOCK = 64  # points whose winding numbers are summed over all triangles in one numpy call


def winding_numbers(triangles: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(k,) the winding number of a closed triangle surface (f, 3, 3) about points x (k, 3): 1 inside, 0 outside
    (the triangles' solid angles, Van Oosterom and Strackee, over 4 pi)."""
    out = np.empty(len(x))
    for start in range(0, len(x), WINDING_BLOCK):
        v = triangles[None] - x[start:start + WINDING_BLOCK, None, None, :]  # (b, f, 3, 3): vertices from the point
        a, b, c = v[:, :, 0], v[:, :, 1], v[:, :, 2]
        la, lb, lc = (np.linalg.norm(u, axis=2) for u in (a, b, c))
        det = np.einsum("bfi,bfi->bf", a, np.cross(b, c))
        div = (la * lb * lc + np.einsum("bfi,bfi->bf", a, b) * lc + np.einsum("bfi,bfi->bf", b, c) * la
               + np.einsum("bfi,bfi->bf", c, a) * lb)
        out[start:start + WINDING_BLOCK] = np.arctan2(det, div).sum(axis=1) / (2 * np.pi)
    return out


def palm_inside(search: GraspSearch, H: np.ndarray) -> np.ndarray:
    """(n,) True where a body shape's centre lies inside the object: those behind the tangent plane of their nearest
    object point, and farther from it than the points' spacing, are confirmed by the winding number."""
    inside = np.zeros(len(H), bool)
    for shape in search.hand.body:
        world = H @ shape.placement
        centres = world[:, :3, :3] @ bounding(shape.geometry, np.eye(4))[0] + world[:, :3, 3]
        d, i = search.obj.tree.query(centres)
        behind = np.einsum("ij,ij->i", centres - search.obj.points[i], search.obj.normals[i]) < 0
        suspect = np.flatnonzero(behind & (d > search.obj.step))
        inside[suspect[winding_numbers(search.triangles, centres[suspect]) > 0.5]] = True
    return inside


def body_hits(search: GraspSearch, H: np.ndarray) -> np.ndarray:
    """(n,) True where a body shape hits the object (object points inside it, then coal)."""
    hit = np.zeros(len(H), bool)
    for j, shape in enumerate(search.hand.body):
        world = (H @ shape.placement)[:, None]
        hit |= search.screen.hits(world, [search.body_inside[j]])
        for k in np.flatnonzero(~hit):
            hit[k] = search.test.hits_object(shape.geometry, transform3s(world[k, 0]))
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
