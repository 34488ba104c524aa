"""The local planner: straight lines in joint space, checked densely enough that nothing is missed.

Resolution (a bound on how far robot points move, not a joint-space step): along
q(s) = qa + s (qb - qa), a point of geometry g moves at most sum_j |dq_j| r_j(g), where r_j(g)
bounds the distance from joint j's axis to g (link offsets down the chain + g's farthest hull
vertex, configuration-independent). Relative to each other, the two geometries of a pair move at
most the sum of both bounds over the joints that change their relative pose (joints above both
move them rigidly together), and their distance changes no faster than that. A pair padded by p
(checked as colliding closer than p) whose checks pass at configurations between which it moves at
most 2 (p - c) keeps distance >= c along the whole continuous motion: every intermediate relative
position is within (p - c) of a checked one. A segment is checked at the fewest evenly spaced
configurations that satisfy this for every pair of the subset, in van der Corput order (midpoint
first) so that colliding segments fail early.

Each pair as densely as it needs: the configurations are as many as the pair that moves most needs; a pair that
moves 2^j times less is checked only at every 2^j-th of them (and both ends), which keeps its own bound. The checks
go level by level, every pair at the coarsest (every 2^J-th configuration, the ends), then at each finer level only
the pairs that need it, in van der Corput order within a level. Most pairs past the broad phase move far less than
the one that sets the count (a fingertip sets it; the forearm near the desk does not).

Coarse first (`coarse` k > 1, for motions whose paddings are tight): the segment is checked at every
k-th of those configurations with each pair padded by P = c + k (p - c), so that between two of them
it moves at most 2 (P - c); where both ends of such an interval pass, the pair keeps c along it.
Only the intervals next to a configuration that fails at P are checked at all their configurations
(padding p). Same guarantee, far fewer checks where the motion stays away from things.

Curves (a timed trajectory whose pieces bound each joint's speed, see `Curve`): within a piece of duration h
where joint j moves no faster than w_j, a point of g moves at most h sum_j w_j r_j(g); the same bound, summed over
pieces, is a clock u(t) along which the curve moves no faster than a straight segment of the same length in u.
The curve is checked at evenly spaced values of u (coarse first alike): the guarantee of a straight segment.

A screen of a curve (`screen=True`) makes only its first checks: its SCREEN_LEVELS coarsest levels (or the coarse
configurations, or as many of the van der Corput order), where nearly every curve that fails is found to fail. It
guarantees nothing: a curve that passes it is checked for the rest later (`spans`), only where it is kept
(smoothing.py): the configurations of its own checks that bound the spans kept (for a pair checked at every 2^j-th,
from the last such configuration before a span to the first after it), less those of the screen (a coarse-first
check makes its coarse ones again: their answers decide where the fine ones go). So a curve checked in parts never
costs more checks than checked whole, and every span kept has the guarantee of the whole check.
"""
from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable
from typing import Protocol

import numpy as np

from planner.collision.checker import CollisionChecker, CollisionModel
from planner.collision.pair_tables import pair_table
from planner.collision.schedule import bisection_indices, bounding, coarse_first, level_order


def geometry_radii(cm: CollisionModel, known: np.ndarray | None = None) -> np.ndarray:
    """(n_geometries, nq) r_j(g): a bound on the distance from joint j's axis to geometry g (0 unless j moves g).
    `known`: the rows of the model's first geometries, computed before (a model extended by one more body).

    The first offset below j counts only across the axis (rotating about the axis keeps it); the
    rest of the chain counts in full; the geometry's own extent is its farthest hull vertex
    (a bounding sphere for primitives).
    """
    model = cm.robot.model
    radii = np.zeros((len(cm.geometry.geometryObjects), model.nq))
    skip = 0 if known is None else len(known)
    radii[:skip] = known
    objects = cm.geometry.geometryObjects
    for g in range(skip, len(objects)):
        obj = objects[g]
        if obj.parentJoint == 0:
            continue  # fixed in the world (obstacles, a static object): no joint moves it
        axes = cm.robot.joint_axes
        geom = obj.geometry
        if hasattr(geom, "points"):
            pts = np.asarray(geom.points()) @ obj.placement.rotation.T + obj.placement.translation
            reach = float(np.linalg.norm(pts, axis=1).max())
        else:
            geom.computeLocalAABB()
            reach = float(np.linalg.norm(obj.placement.act(np.asarray(geom.aabb_center)))) + float(geom.aabb_radius)
        chain = list(model.supports[obj.parentJoint])[1:]
        offsets = [model.jointPlacements[k].translation for k in chain]  # read once: each is a copy out of pinocchio
        lengths = [float(np.linalg.norm(t)) for t in offsets]
        for i, j in enumerate(chain):
            if not model.joints[j].shortname().startswith(("JointModelR", "JointModelRevolute")):
                raise ValueError(f"joint '{model.names[j]}' is not revolute: the displacement bound assumes revolute joints")
            below = offsets[i + 1] if i + 1 < len(chain) else None
            across = below - axes[j] * (below @ axes[j]) if below is not None else np.zeros(3)
            rest = sum(lengths[i + 2:])
            radii[g, model.joints[j].idx_q] = float(np.linalg.norm(across)) + rest + reach
    return radii


MAX_LEVEL = 4  # a pair is checked at every 16th configuration at the sparsest: the finest levels hold the savings
SCREEN_LEVELS = 2  # a curve's screen: its coarsest levels (every 16th configuration, then the 8th between them)
FEW_PAIRS = 16  # a level due for this many pairs or fewer tests each on its own, without the broad phase
LEVEL_SUBSETS = 32  # per segment checker, the pair subsets of levels kept with their collision tables (most recent)


def allowances(cm: CollisionModel, env_clearance: float, self_clearance: float, object_clearance: float = 0.0) -> np.ndarray:
    """(n_pairs,) p - c per pair: how much closer than its padding a pair may come between checks."""
    keep = np.full(len(cm.ends), self_clearance)
    keep[cm.subsets["env"]] = env_clearance
    keep[cm.subsets.get("object", [])] = object_clearance
    out = cm.paddings() - cm.twinned(keep)
    if np.any(out <= 0):
        raise ValueError("each padding must exceed the clearance it guarantees")
    return out


class Curve(Protocol):
    """A timed motion: its pieces' breakpoints and, per piece and joint, a bound on the joint's speed in it."""

    def speed_bounds(self) -> tuple[np.ndarray, np.ndarray]: ...

    def positions(self, times: np.ndarray) -> np.ndarray: ...


class SegmentChecker:
    """Checks configurations and straight segments against named pair subsets (one per process); `coarse`: see the
    module (1: every configuration at the paddings). `checker`: collision scratch data to share with other segment
    checkers of the same geometry and pairs at other paddings (each passes its own with every check): pinocchio's
    collision data is costly to make and to hold. `checks` counts this one's own checks."""

    def __init__(self, cm: CollisionModel, env_clearance: float, self_clearance: float = 0.0, object_clearance: float = 0.0,
                 radii: np.ndarray | None = None, coarse: int = 1, checker: CollisionChecker | None = None):
        if coarse < 1:
            raise ValueError(f"the coarse factor must be a whole number >= 1, got {coarse}")
        if checker is not None and (checker.cm.geometry is not cm.geometry or checker.cm.ends is not cm.ends):
            raise ValueError("a shared collision checker must be of the same geometry model and pairs")  # subsets may differ
        self.cm = cm
        self.checker = checker or cm.checker()
        self.checks = 0
        paddings = cm.paddings()
        self._margins = pair_table(cm, paddings)
        radii = geometry_radii(cm) if radii is None else radii
        sweep = cm.relative_joints() * (radii[cm.ends[:, 0]] + radii[cm.ends[:, 1]])
        allow = allowances(cm, env_clearance, self_clearance, object_clearance)
        self._per_pair = sweep / (2.0 * allow)[:, None]
        self._weights: dict[str, np.ndarray] = {}
        self._pair_rows: dict[str, np.ndarray] = {}
        self._levels: OrderedDict[tuple[str, bytes], np.ndarray] = OrderedDict()
        self._leading_rows: dict[tuple[str, bytes], np.ndarray] = {}
        self.coarse = int(coarse)
        self._coarse_margins = pair_table(cm, paddings + (self.coarse - 1) * allow) if coarse > 1 else None
        self._clocks: tuple = (None, {})  # (the last curve asked about, its clock per subset): see _clock

    def in_collision(self, q: np.ndarray, subset: str, coarse: bool = False) -> bool:
        """One check of q over a subset, at the paddings (or the coarse ones)."""
        self.checks += 1
        return self.checker.in_collision(q, self.cm.subsets[subset], margins=self._coarse_margins if coarse else self._margins)

    def pairs_free(self, q: np.ndarray, pairs: np.ndarray) -> bool:
        """One check of q over some pairs (indices) at the paddings: each tested on its own when they are few (see
        CollisionChecker.few_collide), else as a subset, whose tables the checker keeps by the array's identity (see
        _level_subset, which lets them go)."""
        self.checks += 1
        if len(pairs) <= FEW_PAIRS:
            return not self.checker.few_collide(q, pairs, self._margins)
        return not self.checker.in_collision(q, pairs, margins=self._margins)

    def colliding_pairs(self, q: np.ndarray, subset: str) -> list[tuple[str, str]]:
        """The subset's pairs colliding at q at the paddings, by geometry name (for messages)."""
        return self.checker.colliding_pairs(q, self.cm.subsets[subset], self._margins)

    def weights(self, subset: str) -> np.ndarray:
        """(rows, nq) the subset's displacement weights per joint (computed once per subset)."""
        if subset not in self._weights:
            rows = np.ascontiguousarray(self._per_pair[self.cm.subsets[subset]])
            # distinct rows, found by their bytes (np.unique(axis=0) sorts lexicographically: much slower)
            _, first, inverse = np.unique(rows.view(np.dtype((np.void, rows.itemsize * rows.shape[1]))).ravel(),
                                          return_index=True, return_inverse=True)
            rank = np.empty(len(first), dtype=int)
            rank[np.argsort(first, kind="stable")] = np.arange(len(first))
            self._weights[subset] = rows[np.sort(first)]
            self._pair_rows[subset] = rank[inverse.ravel()]  # each pair's row
        return self._weights[subset]

    def pair_levels(self, subset: str, need: np.ndarray, n: int) -> np.ndarray | None:
        """Per pair of the subset, j such that checking it at every 2^j-th of n configurations keeps its bound, given
        `need` per row of `weights(subset)`: how many of the n - 1 intervals its displacement spans at most; None when
        every pair needs every configuration."""
        if n < 3:
            return None
        top = min(MAX_LEVEL, int(np.log2(n - 1)))
        with np.errstate(divide="ignore"):
            rows = np.floor(np.log2((n - 1) / np.maximum(need, 0.0)))
        rows = np.clip(np.nan_to_num(rows, posinf=top), 0, top).astype(int)
        return rows[self._pair_rows[subset]] if rows.any() else None

    def steps(self, qa: np.ndarray, qb: np.ndarray, subset: str) -> np.ndarray:
        """Configurations checked on each segment qa[i] -> qb[i] (vectorised; both ends included)."""
        return self._steps(self._sweep(qa, qb, subset))

    def _sweep(self, qa: np.ndarray, qb: np.ndarray, subset: str) -> np.ndarray:
        """(segments, rows) how many allowed displacements each row of `weights(subset)` spans along each segment."""
        return np.abs(np.atleast_2d(qb) - np.atleast_2d(qa)) @ self.weights(subset).T

    @staticmethod
    def _steps(sweep: np.ndarray) -> np.ndarray:
        return np.ceil(sweep.max(axis=1, initial=0.0)).astype(int) + 1

    def free(self, q: np.ndarray, subset: str) -> bool:
        return not self.in_collision(q, subset)

    def segment_free(self, qa: np.ndarray, qb: np.ndarray, subset: str, ends: bool = True) -> bool:
        """True if every check of the segment passes (`ends=False`: the two ends are known free)."""
        return self.first_hit(qa, qb, subset, ends) is None

    def first_hit(self, qa: np.ndarray, qb: np.ndarray, subset: str, ends: bool = True) -> np.ndarray | None:
        """The first configuration of the segment, in checking order, whose check fails; None when all pass."""
        dq = qb - qa
        sweep = self._sweep(qa, qb, subset)
        n = int(self._steps(sweep)[0])
        return self._first_hit(n, lambda s: qa + s * dq, subset, ends, self.pair_levels(subset, sweep[0], n))

    def most_curve_checks(self, curve: Curve, subset: str) -> int:
        """The most checks a curve's check can make: its configurations, and coarse first (see two_level) each coarse
        one a second time at the paddings."""
        n = int(np.ceil(self._clock(curve, subset)[-1][-1])) + 1
        grid = self._grid(n)
        return n if grid == n else grid + (grid - 1) // self.coarse + 1

    def _clock(self, curve: Curve, subset: str) -> tuple[np.ndarray, ...]:
        """(breakpoints, speed bounds, moving joints, the clock's rate per part, the clock at the breakpoints) of a curve
        (see the module), kept for the last curve asked about (per subset): its counts, then its checks."""
        if self._clocks[0] is not curve:
            self._clocks = (curve, {})
        if subset not in self._clocks[1]:
            t, bound = curve.speed_bounds()
            moving = np.flatnonzero(bound.max(axis=0) > 0)
            rates = np.einsum("kj,rj->kr", bound[:, moving], self._leading(subset, moving)).max(axis=1)  # no BLAS threads in a worker
            clock = np.concatenate([[0.0], np.cumsum(rates * np.diff(t))])
            self._clocks[1][subset] = (t, bound, moving, rates, clock)
        return self._clocks[1][subset]

    def curve_first_hit(self, curve: Curve, subset: str, ends: bool = True, screen: bool = False,
                        spans: np.ndarray | None = None) -> np.ndarray | None:
        """The first configuration of a curve, in checking order, whose check fails; None when all pass (see the
        module: as many checks as a straight segment moving as far; `ends=False`: both ends are known free; `screen`:
        its first checks only; `spans`: (m, 2) times of the curve, after its screen passed: the rest of its checks
        that bound them)."""
        t, bound, moving, rates, clock = self._clock(curve, subset)
        windows = None if spans is None else np.interp(np.asarray(spans, float), t, clock) / max(clock[-1], 1e-300)
        n = int(np.ceil(clock[-1])) + 1
        grid = self._grid(n)  # every parameter a check may read, evaluated at once
        q = curve.positions(np.interp(np.linspace(0.0, clock[-1], grid), clock, t))
        levels = None
        if grid == n and n >= 3:  # a row moves at most this share of the clock along it: each joint at its largest
            live = rates > 0  # speed per unit of the clock over all pieces (a bound; the exact share costs a product per piece)
            peak = (bound[live][:, moving] / rates[live, None]).max(axis=0, initial=0.0)
            share = np.einsum("j,rj->r", peak, self.weights(subset)[:, moving])
            levels = self.pair_levels(subset, share * clock[-1], n)
        return self._first_hit(n, lambda s: q[int(round(s * (grid - 1)))], subset, ends, levels, screen, windows)

    def _leading(self, subset: str, moving: np.ndarray) -> np.ndarray:
        """The subset's displacement weights over the moving joints without the rows another row bounds everywhere
        (speeds are >= 0: a bounded row never gives the largest displacement): a handful of a thousand, once per set of
        joints. Most checkers see one set (a ramp's checker is made for the joints its pieces move): the first is picked
        among all rows; from a second on, among the rows no other bounds over all joints (bounded there, bounded over
        any of them), found then."""
        key = (subset, moving.tobytes())
        if key not in self._leading_rows:
            rows = self.weights(subset)
            if any(k[0] == subset for k in self._leading_rows):  # a second set of joints (or more)
                every = (subset, b"")
                if every not in self._leading_rows:
                    self._leading_rows[every] = _undominated(rows)
                rows = self._leading_rows[every]
            self._leading_rows[key] = _undominated(rows[:, moving])
        return self._leading_rows[key]

    def _grid(self, n: int) -> int:
        """How many evenly spaced parameters the checks of n configurations may read (coarse first: see coarse_first)."""
        if self._coarse_margins is not None and n > 2 * self.coarse + 1:
            return -(-(n - 1) // self.coarse) * self.coarse + 1
        return n

    def _first_hit(self, n: int, at: Callable[[float], np.ndarray], subset: str, ends: bool,
                   levels: np.ndarray | None = None, screen: bool = False,
                   windows: np.ndarray | None = None) -> np.ndarray | None:
        """The first of n evenly spaced configurations at(s), s in 0..1, whose check fails (coarse first, or each pair
        at its `levels`: see the module); None when all pass (`screen`: its first checks only; `windows`: (m, 2)
        parameters, after the screen passed: the rest of the checks that bound them)."""
        if self._grid(n) != n:
            s = coarse_first(n, self.coarse, lambda s, coarse: self.in_collision(at(s), subset, coarse), ends, screen,
                             windows)
            return None if s is None else at(s)
        if levels is not None:
            return self._by_levels(n, at, subset, ends, levels, screen, windows)
        order = bisection_indices(n)
        first = order if ends else order[2:]
        cut = (n - 1) // 2 ** (MAX_LEVEL + 1 - SCREEN_LEVELS) + 2  # as many as the levels' screen
        for i in first[:cut] if screen else first if windows is None else bounding(first[cut:], windows, n):
            q = at(i / max(n - 1, 1))
            if self.in_collision(q, subset):
                return q
        return None

    def _by_levels(self, n: int, at: Callable[[float], np.ndarray], subset: str, ends: bool, levels: np.ndarray,
                   screen: bool = False, windows: np.ndarray | None = None) -> np.ndarray | None:
        """_first_hit with pair p checked only at the multiples of 2^levels[p] (and the ends), coarsest level first
        (`screen`: the SCREEN_LEVELS coarsest only; `windows`: the finer ones, where they bound the windows)."""
        order = level_order(n, int(levels.max()))
        for j, indices in order[:SCREEN_LEVELS] if screen else order if windows is None else order[SCREEN_LEVELS:]:
            due = levels <= j
            pairs = self.cm.subsets[subset][due] if int(due.sum()) <= FEW_PAIRS else self._level_subset(subset, due)
            for i in indices if windows is None else bounding(indices, windows, n, 2**j):
                if not ends and (i == 0 or i == n - 1):
                    continue
                q = at(i / (n - 1))
                if not self.pairs_free(q, pairs):
                    return q
        return None

    def _level_subset(self, subset: str, due: np.ndarray) -> np.ndarray:
        """The subset's pairs marked `due`: the subset's own array when all are, else one kept (with the collision
        tables the checker makes for it) among the most recent LEVEL_SUBSETS."""
        pairs = self.cm.subsets[subset]
        if due.all():
            return pairs
        key = (subset, np.packbits(due).tobytes())
        if key in self._levels:
            self._levels.move_to_end(key)
        else:
            self._levels[key] = pairs[due]
            if len(self._levels) > LEVEL_SUBSETS:
                self.checker.forget(self._levels.popitem(last=False)[1])
        return self._levels[key]


def _undominated(rows: np.ndarray) -> np.ndarray:
    """The rows no other row bounds in every column (of equal rows, one), largest sum first: each row kept drops those
    it bounds from the rest, so the work shrinks with every row kept (most of a thousand rows go with the first few)."""
    rest = rows[np.argsort(-rows.sum(axis=1), kind="stable")]
    kept = []
    while len(rest):
        kept.append(rest[0])
        rest = rest[1:][~np.all(rest[1:] <= rest[0], axis=1)]
    return np.array(kept).reshape(len(kept), rows.shape[1])
