"""The robot's self-collision pair set: which pairs of its simplified geometries are checked, computed once and cached.

Disabled: adjacent links, links on one joint, pairs colliding at the rest configuration (as MoveIt's
setup assistant does) and link pairs the robot spec allows to touch (`allowed_collisions`, as an
SRDF's disable_collisions); pairs never within `prune_margin` over `prune_samples` uniform samples are
pruned. Pairs between the two arms (hands included) are never pruned: the arms share a workspace, and
uniform samples rarely bring the hands together. The pair set is cached per robot spec, URDFs and
parameters in the user cache.
"""
from __future__ import annotations

import functools
import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from planner.core.results import atomic_write_text
from planner.core.user_cache import cache_path, read_cached
from planner.model.robot import Robot

CODE_VERSION = "pairs-3"


@dataclass(frozen=True)
class CollisionParams:
    """How the simplified model is made; part of the pair cache key."""

    prune_margin: float = 0.05  # m: a pair never closer than this in the samples is pruned
    prune_samples: int = 4000
    env_padding: float = 0.01  # m: robot-obstacle pairs count as colliding closer than this
    self_padding: float = 0.0  # m: robot-robot pairs count as colliding closer than this
    seed: int = 0
    object_padding: float = 0.0  # m: robot-object pairs (subset 'object', when the model has the object) likewise


@dataclass(frozen=True)
class PairSet:
    """Which robot self-collision pairs are checked, and why the others are not."""

    kept: tuple[tuple[str, str], ...]
    adjacent: int
    at_rest: int
    pruned: int
    allowed: int  # pairs of links the robot spec allows to touch (allowed_collisions)

    def to_json(self) -> str:
        return json.dumps({"kept": self.kept, "adjacent": self.adjacent, "at_rest": self.at_rest, "pruned": self.pruned,
                           "allowed": self.allowed})

    @staticmethod
    def from_json(text: str) -> "PairSet":
        d = json.loads(text)
        kept = tuple(tuple(p) for p in d["kept"])
        counts = (d["adjacent"], d["at_rest"], d["pruned"], d["allowed"])
        if not all(len(p) == 2 and all(isinstance(n, str) for n in p) for p in kept) or not all(type(c) is int for c in counts):
            raise ValueError("expected 'kept' as pairs of geometry names and integer counts")
        return PairSet(kept, *counts)


def geometry_part(robot: Robot, gm: pin.GeometryModel, index: int) -> str:
    """The part a geometry belongs to: an arm name, '<arm>_hand', or 'torso' (fixed base included)."""
    obj = gm.geometryObjects[index]
    for arm in robot.spec.arms:
        if obj.name.startswith(arm.hand.prefix):
            return f"{arm.name}_hand"
    q = robot.model.joints[obj.parentJoint].idx_q if obj.parentJoint > 0 else -1
    for name, idx in robot.arm_idx.items():
        if q in idx:
            return name
    return "torso"


def geometry_link(name: str) -> str:
    """The URDF link of a geometry pinocchio named '<link>_<k>'."""
    link, _, k = name.rpartition("_")
    return link if k.isdigit() else name


def _candidate_pairs(robot: Robot, gm: pin.GeometryModel) -> tuple[list[tuple[int, int]], int, int]:
    """(pairs, adjacent, allowed): all pairs of robot geometries on different, non-adjacent joints (and not both on the
    base) whose links the spec does not allow to touch; how many pairs each rule disabled."""
    parents = robot.model.parents
    allowed_links = {frozenset(p) for p in robot.spec.allowed_collisions}
    links = [geometry_link(o.name) for o in gm.geometryObjects]
    out, adjacent, allowed = [], 0, 0
    n = len(gm.geometryObjects)
    for i in range(n):
        for j in range(i + 1, n):
            a, b = gm.geometryObjects[i].parentJoint, gm.geometryObjects[j].parentJoint
            if a == b or parents[a] == b or parents[b] == a:
                adjacent += 1
            elif frozenset((links[i], links[j])) in allowed_links:
                allowed += 1
            else:
                out.append((i, j))
    return out, adjacent, allowed


def _pair_cache_key(robot: Robot, params: CollisionParams) -> str:
    h = hashlib.sha256(CODE_VERSION.encode())
    h.update(robot.spec.text().encode())
    for path in [robot.spec.body_urdf] + [a.hand.urdf for a in robot.spec.arms]:
        h.update(path.read_bytes())
    h.update(repr((params.prune_margin, params.prune_samples, params.seed)).encode())
    return h.hexdigest()[:20]


def compute_pair_set(robot: Robot, gm: pin.GeometryModel, params: CollisionParams) -> PairSet:
    """Sample the robot to find the self-collision pairs worth checking (see module docstring)."""
    pairs, adjacent, allowed = _candidate_pairs(robot, gm)
    work = gm.copy()
    work.removeAllCollisionPairs()
    for i, j in pairs:
        work.addCollisionPair(pin.CollisionPair(i, j))
    data, gd = robot.model.createData(), pin.GeometryData(work)
    pin.computeCollisions(robot.model, data, work, gd, robot.q_rest, False)
    at_rest = np.array([r.isCollision() for r in gd.collisionResults])
    for k in range(len(pairs)):
        gd.collisionRequests[k].security_margin = params.prune_margin
        if at_rest[k]:
            gd.deactivateCollisionPair(k)
    arm_of = [geometry_part(robot, gm, i).removesuffix("_hand") for i in range(len(gm.geometryObjects))]
    near = np.array([arm_of[i] != arm_of[j] and "torso" not in (arm_of[i], arm_of[j]) for i, j in pairs]) & ~at_rest
    for k in np.flatnonzero(near):
        gd.deactivateCollisionPair(int(k))
    undecided = np.flatnonzero(~at_rest & ~near)
    rng = np.random.default_rng(params.seed)
    results = gd.collisionResults
    for _ in range(params.prune_samples):
        q = rng.uniform(robot.lower, robot.upper)
        pin.computeCollisions(robot.model, data, work, gd, q, False)
        hit = [k for k in undecided if results[int(k)].isCollision()]
        if hit:
            near[hit] = True
            for k in hit:
                gd.deactivateCollisionPair(int(k))
            undecided = np.setdiff1d(undecided, hit)
    names = [o.name for o in gm.geometryObjects]
    kept = tuple((names[i], names[j]) for (i, j), k in zip(pairs, near) if k)
    return PairSet(kept, adjacent, int(at_rest.sum()), int((~near & ~at_rest).sum()), allowed)


def robot_pair_set(robot: Robot, gm: pin.GeometryModel, params: CollisionParams, use_cache: bool = True) -> PairSet:
    """The pair set, from the user cache when the spec, URDFs and parameters are unchanged."""
    path = cache_path("collision_pairs", f"{_pair_cache_key(robot, params)}.json")
    if use_cache:
        cached = read_cached([path], lambda: _read_pair_set(path, _file_version(path)), "self-collision pair set")
        if cached is not None:
            return cached
    pairs = compute_pair_set(robot, gm, params)
    atomic_write_text(path, pairs.to_json())
    return pairs


@functools.lru_cache(maxsize=8)
def _read_pair_set(path: Path, version: tuple[int, int, int]) -> PairSet:
    """A cached pair set file parsed once per process while it is unchanged (a model is built for every plan; the file is
    large)."""
    return PairSet.from_json(path.read_text())


def _file_version(path: Path) -> tuple[int, int, int]:
    """(inode, size, mtime): a cache entry rewritten (atomically: a new inode) or edited in place reads as another version."""
    st = path.stat()
    return st.st_ino, st.st_size, st.st_mtime_ns
