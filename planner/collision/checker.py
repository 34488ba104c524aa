"""Fast collision checking of the robot against itself and the environment (pinocchio + coal).

Geometry: each link mesh is replaced by its convex hull, which contains it (primitives are kept).
Pairs: the robot's self-collision pair set (planner/collision/pairs.py) and every moving robot
geometry against every obstacle. Robot-obstacle pairs collide within `env_padding` (a security
margin, which the broad phase inflates its boxes by). A check runs pinocchio's naive broad phase (every
pair of boxes, then the subset's pairs whose boxes meet): with some seventy geometries it beat sweep-and-prune and
a dynamic AABB tree over the motion step's checks (docs/benchmarks.md).
"""
from __future__ import annotations

import dataclasses
import functools
from collections import OrderedDict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType

import coal
import numpy as np
import pinocchio as pin

from planner.collision.pair_tables import Screen, active_table, pair_table, screen_of
from planner.collision.pairs import CollisionParams, PairSet, geometry_part, robot_pair_set
from planner.collision.shapes import convex_geometry, is_mesh
from planner.model.environment import Environment
from planner.model.geometry import se3
from planner.model.robot import Robot

MEASURED = 64  # configurations whose measured distances a checker keeps (see CollisionChecker.measured)


def simplified_robot_geometry(robot: Robot) -> pin.GeometryModel:
    """The robot's collision model with every mesh replaced by its convex hull (a copy)."""
    return _simplified(robot).copy()


@functools.lru_cache(maxsize=8)
def _simplified(robot: Robot) -> pin.GeometryModel:
    gm = robot.collision_model.copy()
    for obj in gm.geometryObjects:
        if is_mesh(obj.geometry):
            obj.geometry = convex_geometry(obj)
            obj.meshPath = ""
    return gm


@dataclass(frozen=True, eq=False)
class CollisionModel:
    """Robot hulls + obstacles in one pinocchio GeometryModel, with the pairs of each subset.

    Subsets: 'all', 'self', 'env', '<arm>' (the arm and its hand against everything),
    '<arm>_env', '<arm>_hand' (the hand against everything), 'hands' (one hand against the other).
    Shared read-only (its subsets a read-only mapping of read-only arrays, like `ends`, `support` and `twins`); each
    thread or process makes its own `checker()`, and a changed model is a new one (`with_subsets`, `dataclasses.replace`).
    """

    robot: Robot
    geometry: pin.GeometryModel
    pair_set: PairSet
    params: CollisionParams
    n_robot_geoms: int
    parts: tuple[str, ...]
    subsets: Mapping[str, np.ndarray]
    ends: np.ndarray  # (n_pairs, 2) the geometry indices of each collision pair (read once: the pair list is slow to walk)
    support: np.ndarray  # (n_geometries, nq) bool: the joints that move each geometry
    pair_padding: tuple[tuple[int, float], ...] = ()  # (pair, padding): pairs padded otherwise than their kind
    twins: np.ndarray | None = None  # (n_pairs,) the pair a screening pair stands for (a hull for its mesh), else -1

    def __post_init__(self):
        subsets = {name: _read_only(np.asarray(pairs)) for name, pairs in self.subsets.items()}
        object.__setattr__(self, "subsets", MappingProxyType(subsets))
        for a in (self.ends, self.support, self.twins):
            if a is not None:
                _read_only(a)

    def checker(self) -> "CollisionChecker":
        return CollisionChecker(self)

    def paddings(self) -> np.ndarray:
        """(n_pairs,) each pair's padding: its kind's ('env', 'object', else 'self') unless `pair_padding` names it."""
        out = np.full(len(self.ends), self.params.self_padding)
        out[self.subsets["env"]] = self.params.env_padding
        out[self.subsets.get("object", [])] = self.params.object_padding
        for pair, padding in self.pair_padding:
            out[pair] = padding
        return self.twinned(out)

    def twinned(self, per_pair: np.ndarray) -> np.ndarray:
        """A per-pair value with each screening pair given its twin's (in place)."""
        if self.twins is not None:
            screening = self.twins >= 0
            per_pair[screening] = per_pair[self.twins[screening]]
        return per_pair

    def relative_joints(self) -> np.ndarray:
        """(n_pairs, nq) bool: the joints whose motion changes each pair's relative pose (a joint above both geometries
        moves them rigidly together, so it is not one of them)."""
        return self.support[self.ends[:, 0]] ^ self.support[self.ends[:, 1]]

    def with_subsets(self, extra: dict[str, np.ndarray]) -> "CollisionModel":
        """The same model with more named pair subsets (pair indices), for a caller's own checks."""
        return dataclasses.replace(self, subsets={**self.subsets, **extra})


def moved_by_fingers(robot: Robot, objects: Sequence[pin.GeometryObject], arm: str) -> np.ndarray:
    """Indices, among the robot geometries `objects`, of those moved by an arm's finger joints."""
    model = robot.model
    fingers = set(robot.hand_idx[arm].tolist())
    return np.array([g for g, o in enumerate(objects) if o.parentJoint > 0 and model.joints[o.parentJoint].idx_q in fingers],
                    dtype=np.int64)


def build_collision_model(robot: Robot, environment: Environment = (), params: CollisionParams = CollisionParams(),
                          use_cache: bool = True) -> CollisionModel:
    """Simplify the robot, choose its pairs (cached), add the obstacles and index the subsets."""
    gm = simplified_robot_geometry(robot)
    pair_set = robot_pair_set(robot, gm, params, use_cache)
    n_robot = len(gm.geometryObjects)
    parts = tuple(geometry_part(robot, gm, i) for i in range(n_robot))
    for ob in environment:
        gm.addGeometryObject(pin.GeometryObject(f"env/{ob.name}", 0, 0, se3(ob.pose), ob.coal_shape()))
    index = {o.name: i for i, o in enumerate(gm.geometryObjects)}
    robot_pairs = [(index[a], index[b]) for a, b in pair_set.kept]
    # the fixed base against fixed obstacles is checked once, by `check` of the task
    env_pairs = [(i, e) for i in range(n_robot) if gm.geometryObjects[i].parentJoint != 0
                 for e in range(n_robot, len(gm.geometryObjects))]
    gm.removeAllCollisionPairs()
    for a, b in robot_pairs + env_pairs:
        gm.addCollisionPair(pin.CollisionPair(a, b))
    n_self = len(robot_pairs)
    ends = np.array(robot_pairs + env_pairs, dtype=np.int64).reshape(-1, 2)  # as added (reading them back from the model is slow)
    first, second = ends[:, 0], ends[:, 1]
    part = np.array(parts + ("env",) * (len(gm.geometryObjects) - n_robot))
    pa, pb = part[first], part[second]
    k = np.arange(len(first))
    subsets = {"all": k, "self": k[:n_self], "env": k[n_self:]}
    for arm in robot.spec.arm_names:
        mine = (pa == arm) | (pb == arm) | (pa == f"{arm}_hand") | (pb == f"{arm}_hand")
        subsets[arm] = k[mine]
        fingers = np.isin(np.arange(len(gm.geometryObjects)), moved_by_fingers(robot, gm.geometryObjects[:n_robot], arm))
        subsets[f"{arm}_no_fingers"] = k[mine & ~fingers[first] & ~fingers[second]]  # reach: open fingers may touch
        subsets[f"{arm}_env"] = k[mine & (k >= n_self)]
        subsets[f"{arm}_hand"] = k[(pa == f"{arm}_hand") | (pb == f"{arm}_hand")]
    hands = [f"{a}_hand" for a in robot.spec.arm_names]
    subsets["hands"] = k[((pa == hands[0]) & (pb == hands[1])) | ((pa == hands[1]) & (pb == hands[0]))]
    support = joint_support(robot.model, [o.parentJoint for o in gm.geometryObjects])
    return CollisionModel(robot, gm, pair_set, params, n_robot, parts, subsets, ends, support)


def _read_only(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


def joint_support(model: pin.Model, parents: list[int]) -> np.ndarray:
    """(len(parents), nq) bool: the joints whose motion moves a geometry on each parent joint (those supporting it)."""
    support = np.zeros((len(parents), model.nq), dtype=bool)
    for g, parent in enumerate(parents):
        for j in list(model.supports[parent])[1:]:
            support[g, model.joints[j].idx_q] = True
    return support


class CollisionChecker:
    """Per-thread scratch data for one CollisionModel: one pinocchio collision data and broad-phase manager for all its
    subsets and paddings, switched to the ones a check asks for (far cheaper than one more collision data, which a forked worker
    also has to copy). A subset is a name of the model's, or the
    pair indices of one (of a model sharing this one's geometry and pairs: see CollisionModel.with_subsets)."""

    def __init__(self, cm: CollisionModel, data: pin.Data | None = None):
        """`data`: pinocchio scratch data to share with other checkers of this thread (each check recomputes it)."""
        self.cm = cm
        self.model = cm.robot.model
        self.data = self.model.createData() if data is None else data
        self._gd: pin.GeometryData | None = None
        self._manager = None
        self._first = None  # the callback that reports the first pair hit (for screens)
        self._collect = None  # the callback that lists the pairs the broad phase finds (see overlapping)
        self._tables: dict[str | int, tuple[np.ndarray, Screen | None, np.ndarray]] = {}  # per subset (name, or id of its
        # indices): its indices (kept, so the id stays theirs), its screen, the pair table it checks
        self._active: np.ndarray | None = None  # the pair table active now
        self._margins: np.ndarray | None = None  # the margins table set now (None: the model's)
        self._own_margins: np.ndarray | None = None
        self._last: tuple | None = None  # (subset, margins, screen) of the last check, while its setting is active
        self._stand_ins: np.ndarray | None = None
        self._measured: OrderedDict[bytes, dict[int, float]] = OrderedDict()  # see measured
        self.checks = 0
        self.pair_tests = 0  # pairs that reached the exact (narrow-phase) test: past the broad phase, active in the subset

    def _entry(self, subset: str | np.ndarray) -> tuple[np.ndarray, Screen | None, np.ndarray]:
        """(pair indices, screen, pair table) of a subset, made once."""
        key = subset if isinstance(subset, str) else id(subset)
        if key not in self._tables:
            if isinstance(subset, str) and subset not in self.cm.subsets:
                raise KeyError(f"unknown collision subset '{subset}' (subsets: {', '.join(self.cm.subsets)})")
            pairs = self.cm.subsets[subset] if isinstance(subset, str) else subset
            screen = screen_of(self.cm, pairs)
            self._tables[key] = (pairs, screen, screen.screened if screen is not None else active_table(self.cm, pairs))
        return self._tables[key]

    def _subset(self, subset: str | np.ndarray, margins: np.ndarray | None = None,
                exact: bool = False) -> tuple[pin.GeometryData, object]:
        """The collision data and manager with the subset's pairs active (screened, unless `exact`) and padded by
        `margins` (a `pair_table`; None: the model's paddings)."""
        _, screen, table = self._entry(subset)
        if exact and screen is not None:
            table = screen.exact
        gm = self.cm.geometry
        if margins is None:
            if self._own_margins is None:
                self._own_margins = pair_table(self.cm, self.cm.paddings())
            margins = self._own_margins
        if self._gd is None:
            self._make_data(table, margins)
        if self._active is not table:
            self._gd.setActiveCollisionPairs(gm, table, True)
            self._active = table
        if self._margins is not margins:
            self._gd.setSecurityMargins(gm, margins, True, False)
            self._margins = margins
        return self._gd, self._manager

    def _make_data(self, table: np.ndarray, margins: np.ndarray) -> None:
        """This checker's one collision data and broad-phase manager, with `table`'s pairs active, padded by `margins`."""
        gm = self.cm.geometry
        self._gd = pin.GeometryData(gm)
        self._gd.setActiveCollisionPairs(gm, table, True)
        self._gd.setSecurityMargins(gm, margins, True, False)
        self._manager = pin.BroadPhaseManager_NaiveCollisionManager(self.model, gm, self._gd)
        self._first = pin.CollisionCallBackDefault(gm, self._gd, True)
        self._active, self._margins = table, margins

    def few_collide(self, q: np.ndarray, pairs: np.ndarray, margins: np.ndarray) -> bool:
        """Whether any of a few pairs (indices) collides at q padded by `margins` (a `pair_table`), each tested on its
        own: no broad phase, whose bounding boxes of every geometry cost more than a handful of exact tests. A pair with
        a screening twin (the object's hull for its mesh) is tested as its twin first."""
        self.checks += 1
        gm = self.cm.geometry
        if self._gd is None:
            self._make_data(active_table(self.cm, pairs), margins)
        if self._margins is not margins:
            self._gd.setSecurityMargins(gm, margins, True, False)
            self._margins, self._last = margins, None
        gd = self._gd
        pin.updateGeometryPlacements(self.model, self.data, gm, gd, q)
        stand_in = self._stand_in()
        for k in pairs:
            screen = stand_in[k]
            self.pair_tests += 1
            if screen >= 0 and not pin.computeCollision(gm, gd, int(screen)):
                continue  # the hull misses: so does the mesh it holds
            self.pair_tests += int(screen >= 0)
            if pin.computeCollision(gm, gd, int(k)):
                return True
        return False

    def _stand_in(self) -> np.ndarray:
        """(n_pairs,) the screening pair standing for each pair (its hull's), else -1 (made once)."""
        if self._stand_ins is None:
            self._stand_ins = np.full(len(self.cm.ends), -1)
            if self.cm.twins is not None:
                screening = self.cm.twins >= 0
                self._stand_ins[self.cm.twins[screening]] = np.flatnonzero(screening)
        return self._stand_ins

    def forget(self, subset: np.ndarray) -> None:
        """Drop what was made for a subset given as pair indices (its tables are kept by the array's identity): its
        owner is about to let it go."""
        self._tables.pop(id(subset), None)
        if self._last is not None and self._last[0] is subset:
            self._last = None

    def in_collision(self, q: np.ndarray, subset: str | np.ndarray = "all", placed: Mapping[int, np.ndarray] | None = None,
                     margins: np.ndarray | None = None) -> bool:
        """True if any pair of the subset collides at q; `placed` (geometry index -> world pose) moves fixed geometries
        for this call, in this checker's own data: the shared model is never written; `margins` (a `pair_table` of
        paddings) pads the pairs otherwise than the model says, for this call. A subset with screening pairs (see
        `CollisionModel.twins`) is checked with them in place of their twins, and as itself only when one of them is the
        first pair hit: a screening geometry holds its twin's, so the answer is the subset's own."""
        self.checks += 1
        if self._last is not None and self._last[0] is subset and self._last[1] is margins:  # as the check before
            screen = self._last[2]
            gd, manager = self._gd, self._manager
        else:
            gd, manager = self._subset(subset, margins)
            screen = self._entry(subset)[1]
            self._last = (subset, margins, screen)
        if placed:
            pin.updateGeometryPlacements(self.model, self.data, self.cm.geometry, gd, q)
            for index, T in placed.items():
                gd.oMg[index] = se3(T)
            manager.update(False)
        first = self._first
        hit = bool(pin.computeCollisions(manager, first) if placed else
                   pin.computeCollisions(self.model, self.data, manager, first, q))
        self.pair_tests += first.count
        if not hit or screen is None:
            return hit
        return self._past_screens(gd, manager, screen, subset)

    def _past_screens(self, gd: pin.GeometryData, manager, screen: Screen, subset: str | np.ndarray) -> bool:
        """After a hit: whether the subset's own pairs collide. A screening pair hit (the object's hull, which holds its
        mesh) is answered by its twin, tested alone. Should the twin miss, the hull has failed as a screen there (a
        hand's fingers in a pocket of the hull, near the object they let go of or close on): the twin takes its place
        in the subset's table from then on (_demote), and one more broad-phase pass collects every pair whose boxes
        overlap (no exact test), tested one by one, a screening pair by its hull, then its twin (and demoted alike)."""
        gm, k = self.cm.geometry, self._first.collisionPairIndex
        if not screen.screening[k] or self._twin_collides(gd, subset, k):
            return True
        if self._collect is None:
            self._collect = pin.CollisionCallBackCollect(gm, gd)
        pin.computeCollisions(manager, self._collect)
        for j in self._collect.pair_indexes:
            if j == k or j == self.cm.twins[k]:
                continue
            self.pair_tests += 1
            if pin.computeCollision(gm, gd, int(j)) and (not screen.screening[j] or self._twin_collides(gd, subset, int(j))):
                return True
        return False

    def _twin_collides(self, gd: pin.GeometryData, subset: str | np.ndarray, k: int) -> bool:
        """Whether the twin of screening pair k (hit) collides; where it does not, the hull failed as a screen there
        and its twin takes its place (_demote)."""
        twin = int(self.cm.twins[k])
        self.pair_tests += 1
        if pin.computeCollision(self.cm.geometry, gd, twin):
            return True
        self._demote(subset, k, twin)
        return False

    def _demote(self, subset: str | np.ndarray, k: int, twin: int) -> None:
        """The subset's screening pair k checked as its twin from now on, in this checker (the table copied once): the
        same answers, one exact test where the hull would take it, its twin's and a pass more."""
        key = subset if isinstance(subset, str) else id(subset)
        pairs, screen, table = self._tables[key]
        if screen is not None and table is screen.screened:
            table = table.copy()
            self._tables[key] = (pairs, screen, table)
        for pair, on in ((k, False), (twin, True)):
            a, b = self.cm.ends[pair]
            table[a, b] = table[b, a] = on
        self._gd.deactivateCollisionPair(k)
        self._gd.activateCollisionPair(twin)
        self._active = table

    def colliding(self, q: np.ndarray, subset: str | np.ndarray = "all", margins: np.ndarray | None = None) -> list[int]:
        """Every pair of the subset colliding at q (no broad phase, no screen: each pair tested), padded as `margins` says
        (None: the model's paddings); `distance` then measures them."""
        self._last = None
        gd, _ = self._subset(subset, margins, exact=True)
        pin.computeCollisions(self.model, self.data, self.cm.geometry, gd, q, False)
        results = gd.collisionResults
        return [int(k) for k in self._entry(subset)[0] if results[int(k)].isCollision()]

    def overlapping(self, q: np.ndarray, subset: str | np.ndarray, margins: np.ndarray) -> list[int]:
        """The pairs of the subset whose bounding boxes, each grown by half its largest margin in `margins`, overlap at q
        (the broad phase alone, no screen): every pair nearer than its margin is among them."""
        self._last = None
        _, manager = self._subset(subset, margins, exact=True)
        if self._collect is None:
            self._collect = pin.CollisionCallBackCollect(self.cm.geometry, self._gd)
        pin.computeCollisions(self.model, self.data, manager, self._collect, q)
        return [int(k) for k in self._collect.pair_indexes]

    def measured(self, q: np.ndarray) -> dict[int, float]:
        """The distances `distance` gave at q so far, by pair, for the caller to add to: one memo for every clearance meter
        of this checker (a situation's meters differ only in the pairs they measure, and the span ends a smoothing fits
        its ramps' checks to are measured for one set of moving joints after another); the last MEASURED configurations."""
        key = q.tobytes()
        if key in self._measured:
            self._measured.move_to_end(key)
        else:
            self._measured[key] = {}
            if len(self._measured) > MEASURED:
                self._measured.popitem(last=False)
        return self._measured[key]

    def distance(self, pair: int) -> float:
        """The distance of a pair where the last check placed the geometries, by coal's own function with a fresh solver:
        pinocchio's per-pair distance functor keeps its GJK state between calls, so the same placement measured again
        after others came out different within the solver's tolerance (a fitted padding, and the checks it spaces, then
        depended on what was measured before: on whether a transit ran in this process or in a worker)."""
        gm, placed = self.cm.geometry, self._gd.oMg
        p = gm.collisionPairs[pair]
        a, b = placed[p.first], placed[p.second]
        return float(coal.distance(gm.geometryObjects[p.first].geometry, coal.Transform3s(a.rotation, a.translation),
                                   gm.geometryObjects[p.second].geometry, coal.Transform3s(b.rotation, b.translation),
                                   coal.DistanceRequest(), coal.DistanceResult()))

    def colliding_pairs(self, q: np.ndarray, subset: str | np.ndarray = "all", margins: np.ndarray | None = None) -> list[tuple[str, str]]:
        """Every colliding pair of the subset at q, by geometry name (slower: for display and reports)."""
        objs, pairs = self.cm.geometry.geometryObjects, self.cm.geometry.collisionPairs
        return [(objs[pairs[k].first].name, objs[pairs[k].second].name) for k in self.colliding(q, subset, margins)]
