"""Each situation's checks, built once per double grasp by one factory and passed to the stages (as OMPL passes a
SpaceInformation): its collision model for each kind of motion, one collision scratch data, its clearance meter, its
validities and the path checks already made.

A situation (where the object is) has one base model; each kind of motion (which hands are off the roadmap's open
values, which coordinates move) has its pairs on it (`for_motion`). All of a situation's motions share its geometry,
so one collision checker (pinocchio's scratch data, costly to make, copied by a forked worker) serves every validity
and clearance meter of that situation, each padding and picking the pairs its own way.
"""
from __future__ import annotations

import functools
from collections.abc import Callable

import numpy as np
import pinocchio as pin

from planner.collision.checker import CollisionChecker, CollisionModel
from planner.collision.segments import geometry_radii
from planner.collision.shapes import coal_convex, coal_mesh
from planner.collision.situation import Situation, for_motion, situation_base
from planner.collision.validity import Clearances, Profile, Validity, far, make_validity
from planner.model.task import Scene


class Checked:
    """A validity whose path checks are each made once per double grasp: the pre-shape search checks the approach,
    shaping and closing of each candidate, and the pieces built from the one it keeps are the same motions."""

    def __init__(self, validity):
        self.validity = validity
        self._hits: dict[bytes, np.ndarray | None] = {}

    def hit(self, path: np.ndarray) -> np.ndarray | None:
        """validity.path_hit(path), once per path."""
        key = path.tobytes()
        if key not in self._hits:
            self._hits[key] = self.validity.path_hit(path)
        return self._hits[key]

    def valid(self, path: np.ndarray) -> bool:
        return self.hit(path) is None

    def collisions(self, path: np.ndarray) -> list[tuple[str, str]]:
        """The colliding pairs where the path's check failed (none when valid): the pre-shape search opens the fingers
        they name."""
        return self.validity.colliding_pairs(self.hit(path))


class MotionChecks:
    """A situation's model for one kind of motion and what checks it over its moving pairs: the clearance meter, the
    clearances measured (once per configuration), the validities (once per profile and paddings)."""

    def __init__(self, model: CollisionModel, checker: CollisionChecker, radii: Callable[[CollisionModel], np.ndarray],
                 transit: Profile):
        self.model, self.checker, self.transit = model, checker, transit
        self._radii = radii
        self._measured: dict[bytes, dict[int, float]] = {}
        self._validities: dict[tuple, Validity] = {}
        self._checked: dict[Profile, Checked] = {}

    @functools.cached_property
    def meter(self) -> Clearances:
        """The clearance measure over the moving pairs, up to what the transit profile can use."""
        return Clearances(self.model, "moving", far(self.transit), self.checker)

    def clearances(self, q: np.ndarray) -> dict[int, float]:
        """The near pairs at q and their distances (see validity.Clearances), measured once per configuration (a
        transit's ends were measured when they were found ready)."""
        key = q.tobytes()
        if key not in self._measured:
            self._measured[key] = self.meter(q)
        return self._measured[key]

    def validity(self, profile: Profile, pair_padding: tuple[tuple[int, float], ...] = ()) -> Validity:
        """The validity over the moving pairs, some pairs padded otherwise (see Clearances.fitted_pairs)."""
        key = (profile, pair_padding)
        if key not in self._validities:
            self._validities[key] = make_validity(self.model, profile, "moving", self._radii(self.model), pair_padding,
                                                     self.checker)
        return self._validities[key]

    def checked(self, profile: Profile) -> Checked:
        """The profile's validity with its path checks kept (see Checked)."""
        if profile not in self._checked:
            self._checked[profile] = Checked(self.validity(profile))
        return self._checked[profile]

    def transit_validities(self, q_start: np.ndarray, q_goal: np.ndarray) -> tuple[Validity, Validity]:
        """(full, near) of a transit between two configurations. `full`, for the whole transit, pads the pairs both ends
        hold close (a hand closed on the object holds its thumb near its own wrist) as the farther end allows: at the
        transit padding no configuration of the phase, no roadmap node, would be valid. `near`, for what touches an end,
        pads every pair either end holds close as the nearer end allows."""
        start, goal = self.clearances(q_start), self.clearances(q_goal)
        closest = {pair: min(start.get(pair, np.inf), goal.get(pair, np.inf)) for pair in start.keys() | goal.keys()}
        held = {pair: max(start[pair], goal[pair]) for pair in start.keys() & goal.keys()}
        return (self.validity(self.transit, self.meter.fitted_pairs(self.transit, held)),
                self.validity(self.transit, self.meter.fitted_pairs(self.transit, closest)))


class Validities:
    """The factory of every situation's checks for one double grasp (see the module); `data` is the pinocchio scratch
    data every check recomputes, shared with the stages' kinematics."""

    def __init__(self, scene: Scene, cm: CollisionModel, transit: Profile, contact: Profile):
        self.robot, self.cm, self.transit, self.contact = scene.robot, cm, transit, contact
        self.shape = coal_mesh(scene.object_mesh)
        self.hull = coal_convex(scene.object_mesh.convex_hull)  # screens the mesh: see situation_model
        self.data: pin.Data = self.robot.model.createData()
        self.open = self.robot.q_rest
        self._robot_radii = geometry_radii(cm)
        self._bases: dict[tuple, CollisionModel] = {}  # per Situation.key
        self._checkers: dict[tuple, CollisionChecker] = {}
        self._motions: dict[tuple, MotionChecks] = {}
        self._object_radii: dict[tuple[int, bytes], np.ndarray] = {}

    def of(self, situation: Situation, q: np.ndarray, moving: np.ndarray) -> MotionChecks:
        """The checks of a situation's motions moving the coordinates `moving` from q: the hands not at the roadmap's
        open values at q are those whose pairs 'changed' (see for_motion)."""
        robot = self.robot
        moved = tuple(a for a in robot.spec.arm_names if not np.allclose(q[robot.hand_idx[a]], self.open[robot.hand_idx[a]]))
        alike = situation.key
        key = (alike, moved, np.asarray(moving).tobytes())
        if key not in self._motions:
            if alike not in self._bases:
                self._bases[alike] = situation_base(self.cm, self.shape, situation, self.hull)
            model = for_motion(self._bases[alike], moved, moving)
            if alike not in self._checkers:
                self._checkers[alike] = CollisionChecker(model, self.data)
            self._motions[key] = MotionChecks(model, self._checkers[alike], self.radii, self.transit)
        return self._motions[key]

    def radii(self, model: CollisionModel) -> np.ndarray:
        """The displacement radii of a situation's model: the robot's, computed once, and the object's, once for each
        place it hangs from (its parent joint and placement)."""
        held = model.geometry.geometryObjects[-1]  # the object or its hull, added last: both hang where it does
        where = (held.parentJoint, held.placement.homogeneous.tobytes())
        if where not in self._object_radii:
            self._object_radii[where] = geometry_radii(model, self._robot_radii)
        return self._object_radii[where]
