"""State and motion validity (OMPL's StateValidityChecker and MotionValidator) for one situation of the object.

One way to ask "is this configuration / this straight motion valid here": a `Validity` checks a
named pair subset of a situation's collision model (see situation.py) with the local planner's
displacement bound (segments.py), so a valid motion keeps every checked pair at least
its clearance apart along the whole continuous segment. Two profiles state the paddings:
`transit` keeps the offline roadmap's clearances (so roadmap edges and new edges guarantee the same),
its paddings lowered per motion, pair by pair, to what the motion's ends allow (`Clearances.fitted_pairs`);
`contact` is tighter, for the short motions that end touching the object (approach, closing, opening, retreat, lift, set-down).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from planner.collision.checker import CollisionChecker, CollisionModel
from planner.collision.pair_tables import pair_table
from planner.collision.schedule import two_level
from planner.collision.segments import FEW_PAIRS, Curve, SegmentChecker, geometry_radii
from planner.core.errors import RegraspError
from planner.core.results import frozen


class StateValidity(Protocol):
    """OMPL's StateValidityChecker: is this configuration valid?"""

    def state_valid(self, q: np.ndarray) -> bool: ...


class MotionValidity(StateValidity, Protocol):
    """OMPL's MotionValidator: is the straight motion between two configurations valid (and how many checks so far)?"""

    @property
    def checks(self) -> int: ...

    def motion_valid(self, qa: np.ndarray, qb: np.ndarray, ends: bool = True) -> bool: ...


@dataclass(frozen=True)
class Profile:
    """Paddings (checked as colliding closer than) and the clearances every motion keeps, in metres."""

    name: str
    env_padding: float
    env_clearance: float
    self_padding: float
    self_clearance: float
    object_padding: float  # robot–object pairs
    object_clearance: float
    coarse: int = 1  # segments checked coarse first at this factor (see segments.py); 1: densely throughout

    def describe(self) -> dict:
        """The paddings and clearances, and the largest relative displacement between two checks of each kind of pair (and
        `coarse` times that between two checks that found nothing within `coarse` times a padding's margin over its
        clearance)."""
        return {**{k: v for k, v in dataclasses.asdict(self).items() if k != "name"},
                "obstacle_step_m": round(2 * (self.env_padding - self.env_clearance), 6),
                "robot_step_m": round(2 * (self.self_padding - self.self_clearance), 6),
                "object_step_m": round(2 * (self.object_padding - self.object_clearance), 6)}


def transit_profile(roadmap_resolution: dict, env_padding: float, self_padding: float) -> Profile:
    """Online transit checks keep the roadmap's clearances (read from its recorded resolution), so a path mixing
    roadmap edges and new ones guarantees one thing; paddings closer to them check more densely but accept
    configurations nearer the obstacles (the exchange holds the arms close to the torso). The object is padded like
    the robot."""
    r = roadmap_resolution
    env_clearance, self_clearance = float(r["env_clearance_m"]), float(r["self_clearance_m"])
    if env_padding <= env_clearance or self_padding <= self_clearance:
        raise RegraspError(f"step 'motion': parameters transit_env_padding ({env_padding:g} m) and transit_self_padding "
                           f"({self_padding:g} m) must exceed the roadmap's clearances ({env_clearance:g} m, {self_clearance:g} m)")
    return Profile("transit", env_padding, env_clearance, self_padding, self_clearance, self_padding, self_clearance)


@dataclass(frozen=True, eq=False)
class Validity:
    """Checks states and straight segments of one collision model over one pair subset, at the profile's resolution.

    The segment checker holds scratch data: one per thread or process.
    """

    seg: SegmentChecker
    profile: Profile
    subset: str = "all"

    def on(self, subset: str) -> "Validity":
        """The same model and scratch data over another subset (e.g. 'changed' for roadmap edges)."""
        return dataclasses.replace(self, subset=subset)

    @property
    def checks(self) -> int:
        return self.seg.checks

    def state_valid(self, q: np.ndarray) -> bool:
        return self.seg.free(q, self.subset)

    def motion_valid(self, qa: np.ndarray, qb: np.ndarray, ends: bool = True) -> bool:
        """Every check of the straight segment passes (`ends=False`: both ends are known valid)."""
        return self.seg.segment_free(qa, qb, self.subset, ends)

    def curve_valid(self, curve: Curve, ends: bool = True, screen: bool = False, spans: np.ndarray | None = None) -> bool:
        """Every check of a timed curve passes (see segments.py; `ends=False`: both ends are known valid; `screen`: its
        first checks, a screen that guarantees nothing; `spans`: after its screen passed, the rest of its checks that
        bound these time spans)."""
        return self.seg.curve_first_hit(curve, self.subset, ends, screen, spans) is None

    def curve_checks(self, curve: Curve) -> int:
        """The most checks a curve's whole check can make."""
        return self.seg.most_curve_checks(curve, self.subset)

    def samples(self, qa: np.ndarray, qb: np.ndarray, subset: str | None = None) -> int:
        """How many evenly spaced configurations a segment is checked at (its resolution), for this or another subset."""
        return int(self.seg.steps(qa, qb, subset or self.subset)[0])

    def colliding_pairs(self, q: np.ndarray | None) -> list[tuple[str, str]]:
        """The pairs of the subset colliding at q, by geometry name (none for None: for messages and pre-shape choices)."""
        return [] if q is None else self.seg.colliding_pairs(q, self.subset)

    def first_collision(self, path: np.ndarray) -> list[tuple[str, str]]:
        """The colliding pairs where a polyline first fails its checks (see path_hit)."""
        return self.colliding_pairs(self.path_hit(path))

    def path_hit(self, path: np.ndarray) -> np.ndarray | None:
        """The first configuration whose check fails, its states checked first, then its segments in order; None when
        the polyline is valid (every state and every segment)."""
        hit = next((q for q in path if not self.state_valid(q)), None)
        for a, b in zip(path[:-1], path[1:]):
            if hit is not None:
                break
            hit = self.seg.first_hit(a, b, self.subset, ends=False)
        return hit

    def path_valid(self, path: np.ndarray) -> bool:
        """Every state and every segment of a polyline."""
        return self.path_hit(path) is None


@dataclass(frozen=True, eq=False)
class Graded:
    """A motion validity checking a segment at `coarse`'s paddings and resolution, and at `fine`'s (lower paddings,
    denser) only next to configurations that fail at coarse's: a transit end held close to something (an object just
    lifted off the desk) needs dense checks beside it, not along the whole segment. Every interval between two checked
    configurations is spanned at the resolution of the paddings both its ends passed at, so a valid motion keeps fine's
    clearances (the same as coarse's) along the whole continuous segment. States are fine's."""

    coarse: Validity
    fine: Validity

    def __post_init__(self):
        a, b = self.coarse.seg.cm, self.fine.seg.cm
        if a.ends.shape != b.ends.shape or np.any(a.ends != b.ends) or self.coarse.subset != self.fine.subset:
            raise ValueError("a graded validity needs one model's pairs and subset at two sets of paddings")
        coarse, fine = a.paddings(), b.paddings()
        if self.coarse.profile.name != self.fine.profile.name or np.any(coarse < fine):
            raise ValueError("a graded validity's coarse paddings must be at least its fine ones, for one profile")
        pairs = b.subsets[self.fine.subset]
        finer = fine[pairs] < coarse[pairs]
        if b.twins is not None:
            finer &= b.twins[pairs] < 0  # a screening pair is tested with the pair it stands for (few_collide)
        # what needs a test between two coarse configurations (see two_level): a few pairs, else the whole subset (a
        # checker keeps the tables of every other set of pairs it is given)
        object.__setattr__(self, "_finer", frozen(pairs[finer]) if np.count_nonzero(finer) <= FEW_PAIRS else None)

    @property
    def checks(self) -> int:
        return self.coarse.checks + (self.fine.checks if self.fine.seg is not self.coarse.seg else 0)

    def state_valid(self, q: np.ndarray) -> bool:
        return self.fine.state_valid(q)

    def motion_valid(self, qa: np.ndarray, qb: np.ndarray, ends: bool = True) -> bool:
        """The segment checked on coarse's grid, and on fine's next to what fails there (see two_level; `ends=False`:
        both ends known valid at fine's paddings, checked at coarse's to spare the intervals beside them)."""
        n, m = self.coarse.samples(qa, qb), self.fine.samples(qa, qb)
        if m <= n:
            return self.fine.motion_valid(qa, qb, ends)
        dq = qb - qa
        finer = self._finer
        between = None if finer is None else lambda s: not self.fine.seg.pairs_free(qa + s * dq, finer)
        return two_level(n, m, lambda s, coarse: not (self.coarse if coarse else self.fine).state_valid(qa + s * dq), ends,
                         between) is None

    def curve_valid(self, curve: Curve, ends: bool = True, screen: bool = False, spans: np.ndarray | None = None) -> bool:
        """A timed curve checked at the fine paddings throughout (see Validity.curve_valid)."""
        return self.fine.curve_valid(curve, ends, screen, spans)

    def curve_checks(self, curve: Curve) -> int:
        return self.fine.curve_checks(curve)


KINDS = ("env", "self", "object")


class Clearances:
    """The distances at a configuration of a subset's pairs nearer than `far[kind]` (what a profile cannot use beyond:
    see `far`), by pair, and the smallest per kind: with an obstacle ('env'), robot–object pairs ('object') and
    robot–robot pairs ('self'). `checker`: the model's collision scratch data, shared with its validities.

    Only pairs nearer than `far` are measured: the broad phase with `far` as the margins finds the candidates, whose
    exact distances are computed; measuring every pair cost ten times more, testing every pair at the margin first twice."""

    def __init__(self, cm: CollisionModel, subset: str, far: dict[str, float], checker: CollisionChecker | None = None):
        if checker is not None and checker.cm.geometry is not cm.geometry:
            raise ValueError("a shared collision checker must be of the same geometry model (its distances are by pair)")
        self.cm, self.subset = cm, subset
        self.checker = checker or cm.checker()
        kind = np.full(len(cm.geometry.collisionPairs), "self", dtype=object)
        kind[cm.subsets["env"]] = "env"
        kind[cm.subsets.get("object", [])] = "object"
        self.kind = kind  # of every pair of the model
        margins = dataclasses.replace(cm.params, **{f"{k}_padding": far[k] for k in KINDS})
        self.far = dataclasses.replace(cm, params=margins, pair_padding=()).paddings()  # per pair
        self.margins = pair_table(cm, self.far)

    def __call__(self, q: np.ndarray) -> dict[int, float]:
        """pair -> distance, for the subset's pairs nearer than `far` of their kind at q."""
        near, known = {}, self.checker.measured(q)
        for k in self.checker.overlapping(q, self.cm.subsets[self.subset], self.margins):
            if k not in known:
                known[k] = self.checker.distance(k)
            if known[k] < self.far[k]:
                near[k] = known[k]
        return near

    def by_kind(self, near: dict[int, float]) -> dict[str, float]:
        """The smallest distance of each kind among measured pairs (inf for a kind none of them is)."""
        out = dict.fromkeys(KINDS, np.inf)
        for pair, distance in near.items():
            out[self.kind[pair]] = min(out[self.kind[pair]], distance)
        return out

    def fitted_pairs(self, profile: Profile, near: dict[int, float]) -> tuple[tuple[int, float], ...]:
        """(pair, padding) for every measured pair whose padding `_fit` lowers, lowered for that pair alone: a motion from
        an end near one thing checks densely only where that pair's two geometries move relative to each other (a
        closed thumb near its own wrist moves only with the wrist's last joint)."""
        out = []
        for pair, distance in sorted(near.items()):
            kind = self.kind[pair]
            padding = getattr(profile, f"{kind}_padding")
            lowered = _fit(padding, getattr(profile, f"{kind}_clearance"), distance)
            if lowered != padding:
                out.append((pair, lowered))
        return tuple(out)


def far(profile: Profile) -> dict[str, float]:
    """Per kind of pair, a distance beyond which a clearance changes nothing for the profile (neither `fits` nor a
    fitted padding nor how free a transit end is): a little past padding / 0.9."""
    return {k: 1.01 * getattr(profile, f"{k}_padding") / 0.9 for k in KINDS}


def fits(profile: Profile, clearance: dict[str, float]) -> bool:
    """Whether a configuration with these clearances is valid with paddings fitted to them (see `_fit`): each
    clearance at least its padding, or able to lower it while the clearance guaranteed stays below."""
    return all(clearance[k] > pad or 0.9 * clearance[k] > keep for k, pad, keep in (
        ("env", profile.env_padding, profile.env_clearance), ("self", profile.self_padding, profile.self_clearance),
        ("object", profile.object_padding, profile.object_clearance)))


def _fit(padding: float, keep: float, have: float) -> float:
    """A padding lowered, when the clearance `have` is smaller, to keep 90 % of its margin over the clearance `keep` it
    guarantees (and only where 90 % of `have` exceeds `keep`, see `fits`): checks stay as sparse as a motion's ends allow,
    the guarantee unchanged. The margin left between checks is 90 % of the end's, never below a tenth of `keep`: 90 % of
    `have` itself could leave a hair's breadth (an end 1.2 mm past its clearance checked every 0.16 mm)."""
    lowered = keep + 0.9 * (have - keep)
    return padding if lowered >= padding or 0.9 * have <= keep else lowered


def make_validity(cm: CollisionModel, profile: Profile, subset: str = "all", known_radii: np.ndarray | None = None,
                  pair_padding: tuple[tuple[int, float], ...] = (), checker: CollisionChecker | None = None) -> Validity:
    """A validity of `cm` with the profile's paddings (the model's own are replaced), `pair_padding` ((pair, padding))
    overriding some pairs' (see Clearances.fitted_pairs); `known_radii`: the displacement radii of cm's first geometries
    (geometry_radii of the model a situation extends), so only the object's are computed; `checker`: cm's collision
    scratch data, shared with its other validities (see SegmentChecker)."""
    cm = dataclasses.replace(cm, params=dataclasses.replace(cm.params, env_padding=profile.env_padding,
                                                            self_padding=profile.self_padding, object_padding=profile.object_padding),
                             pair_padding=pair_padding)
    return Validity(SegmentChecker(cm, profile.env_clearance, profile.self_clearance, profile.object_clearance,
                                   geometry_radii(cm, known_radii), profile.coarse, checker), profile, subset)
