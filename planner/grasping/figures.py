"""What the grasp search worked on, for drawing a grasp list (paper IV-A, figs. 2-3): the object's point set with its
kd-tree leaves, and the fingers' workspace sphere hierarchies.

A grasp list stores the grasps, not these models: they depend only on the mesh, the hand and the step's
parameters, so they are recovered on request (from the user cache when the step ran on this machine, else
computed), never while a session is replayed.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from planner.grasping.finger_workspace import hand_workspaces
from planner.grasping.grasp_list import GraspList, GraspParams, search_object
from planner.model.hand_model import HandModel


@dataclass(frozen=True, eq=False)
class ObjectPoints:
    """The object's point set (object frame) and the kd-tree leaf holding each point."""

    points: np.ndarray  # (m, 3)
    leaves: np.ndarray  # (m,)


@dataclass(frozen=True, eq=False)
class FingerSpheres:
    """One finger's workspace approximated by spheres (hand frame)."""

    finger: str
    centres: np.ndarray  # (k, 3)
    radii: np.ndarray  # (k,)


def object_points(mesh: trimesh.Trimesh, result: GraspList, params: GraspParams) -> ObjectPoints:
    """The point set the grasp list was searched on (`params`: the step's recorded parameters)."""
    model = search_object(mesh, result.tip_radius, params)
    return ObjectPoints(model.points, model.leaf_ids())


def finger_spheres(hand: HandModel, params: GraspParams) -> tuple[FingerSpheres, ...]:
    """Each finger's workspace spheres that the grasp search used, in the hand's finger order (empty ones left out)."""
    return tuple(FingerSpheres(name, ws.centres, ws.radii)
                 for name, ws in zip(hand.finger_names, hand_workspaces(hand, params.workspace())) if len(ws.radii))
