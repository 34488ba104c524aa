"""The smoothing's lazy checks (planner/motion/tentative.py, segments.py): a curve screened by its first checks, then
checked for the rest only where it is kept, tests every pair there as densely as its whole check would (measured by
kinematics alone) and never more often; the parts of kept shortcuts are followed through later shortcuts; a
shortcut kept on a screen that fails where it survives is never in the result."""
from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path

import numpy as np
import pytest
from oracle import motion_collisions
from test_motion import unsmoothed_duration
from test_pair_levels import PairMotion, _recording, random_ramp

from planner.collision.segments import SegmentChecker
from planner.core.forked import cpu_budget
from planner.core.runner import run_pipeline
from planner.core.session import Session
from planner.motion.ramps import ramp
from planner.motion.tentative import Outcome, Survivors
from planner.motion.trajectory import rest_to_rest

EXAMPLE = Path(__file__).resolve().parent.parent / "sessions" / "default-example"


@pytest.fixture(scope="module")
def padded(default_collision):
    cm = default_collision
    return dataclasses.replace(cm, params=dataclasses.replace(cm.params, env_padding=0.03, self_padding=0.012))


@pytest.mark.slow
def test_a_curve_checked_for_the_rest_where_it_is_kept_tests_each_pair_there_as_its_whole_check_would(
        default_scene, padded, monkeypatch):
    """Random parabolic ramps from the rest pose, free by their whole check: screened, then checked for the rest over
    one or two random spans. The two together make some of the whole check's configurations, never more; and every
    pair tested less densely than the curve's count is tested, over each span, from a configuration at or before it to
    one at or after it, moving between two of its tests (measured by kinematics on 600 samples of the curve) no more
    than twice its margin over its clearance."""
    cm, env_c, self_c = padded, 0.01, 0.004
    seg = SegmentChecker(cm, env_c, self_c)
    checks = _recording(seg, monkeypatch)
    allow = cm.paddings() - np.where(np.isin(np.arange(len(cm.ends)), cm.subsets["env"]), env_c, self_c)
    rng = np.random.default_rng(8)
    curves = spared = 0
    while curves < 3:
        curve = random_ramp(default_scene.robot, rng, 0.35)
        checks.clear()
        if curve is None or seg.curve_first_hit(curve, "env") is not None:
            continue
        curves += 1
        whole = {(q.tobytes(), pairs.tobytes()) for q, pairs in checks}
        count = len(checks)
        checks.clear()
        assert seg.curve_first_hit(curve, "env", screen=True) is None
        cuts = np.sort(rng.uniform(0.0, curve.duration, 4))
        spans = cuts.reshape(2, 2)[: 1 + curves % 2]
        assert seg.curve_first_hit(curve, "env", spans=spans) is None
        made = [(q.tobytes(), pairs.tobytes()) for q, pairs in checks]
        assert len(made) == len(set(made)) and set(made) <= whole, "only the whole check's configurations, each once"
        spared += count - len(made)

        motion = PairMotion(cm, curve, 600)
        at = np.array([motion.sample_of(q) for q, _ in checks])
        counts = np.zeros(len(cm.ends), int)
        for _, tested in checks:
            counts[tested] += 1
        sparse = [int(k) for k in cm.subsets["env"] if 0 < counts[k] < len(checks)]
        for k in rng.choice(sparse, min(20, len(sparse)), replace=False):
            world = motion.points(k)
            tested = np.unique(at[[k in set(t.tolist()) for _, t in checks]])
            for t1, t2 in spans:
                first = np.searchsorted(motion.times, t1, "right") - 1
                last = np.searchsorted(motion.times, t2, "left")
                assert tested[0] <= first + 1 and tested[-1] >= last - 1, f"pair {k}: a span not bounded by its tests"
                inside = tested[(tested >= tested[tested <= first + 1][-1]) & (tested <= tested[tested >= last - 1][0])]
                for a, b in zip(inside[:-1], inside[1:]):
                    moved_by = float(np.linalg.norm(world[a:b + 1] - world[a], axis=2).max())
                    assert moved_by <= 2 * allow[k] + 2e-4, f"pair {k} moved {moved_by:.4f} m between two of its tests"
    assert spared > 0, "checking the spans alone spared none of the whole checks"


def test_the_parts_of_kept_shortcuts_follow_the_trajectory_through_later_shortcuts():
    """Random shortcuts spliced into a rest-to-rest trajectory one after another: every part the bookkeeping keeps is
    the trajectory there (its shortcut's motion at the part's own times), the parts never overlap, and what is held
    back for their checks is the sum over the shortcuts that still have a part not checked: every third shortcut is
    checked whole when kept, and none of its parts is ever held back for again, however it is cut."""
    rng = np.random.default_rng(2)
    vmax, amax = np.array([1.0, 0.8, 1.2]), np.array([2.0, 1.5, 2.5])
    traj = rest_to_rest(np.cumsum(rng.normal(0, 1, (9, 3)), axis=0), vmax, amax)
    survivors, kept = Survivors({}), 0
    while kept < 24:
        t1, t2 = np.sort(rng.uniform(0.0, traj.duration, 2))
        (qa, qb), (va, vb) = traj.states(np.array([t1, t2]))
        shortcut = ramp(qa, va, qb, vb, vmax, amax, t2 - t1)
        if shortcut is None:
            continue
        traj = traj.splice(t1, t2, shortcut)
        survivors.splice(kept, Outcome((t1, t2), shortcut, (), 0, 100 + kept, whole=kept % 3 == 0))
        kept += 1
        spans = sorted((p.start + p.a, p.start + p.b) for p in survivors.parts)
        assert all(b1 <= a2 + 1e-9 for (_, b1), (a2, _) in zip(spans[:-1], spans[1:])), "parts overlap"
        for p in survivors.parts:
            assert 0.0 <= p.a < p.b <= survivors.kept[p.seq].shortcut.duration, "a part left its shortcut's own time"
            own = np.linspace(p.a, p.b, 7)
            ramp_q = survivors.kept[p.seq].shortcut.positions(own)
            assert np.allclose(traj.positions(p.start + own), ramp_q, atol=1e-9), "a part is not the trajectory there"
        alive = {p.seq for p in survivors.parts}
        assert survivors.reserved == sum(100 + s for s in alive if s % 3)
    assert len({p.seq for p in survivors.parts}) < kept, "no shortcut was wholly replaced: the case is too easy"
    assert any(p.seq % 3 == 0 and p.a > 0 for p in survivors.parts), "no shortcut checked whole was cut: too easy"


@pytest.mark.slow
def test_a_shortcut_kept_on_a_blind_screen_is_not_in_the_result(tmp_path, monkeypatch):
    """With the curves' levels screened by nothing, the example's smoothing keeps shortcuts whose checks then find them
    colliding where they survive: each is refused and the run smoothed again, the attempts before it replayed. Every
    sample of the motion then passes the independent oracle (which, with the refusals skipped, finds the hands in the
    desk), and the checks stay within the budget."""
    monkeypatch.setattr("planner.collision.segments.SCREEN_LEVELS", 0)
    failed = []
    check = Survivors.check

    def counted(self):
        seq, checks = check(self)
        failed.append(seq is not None)
        return seq, checks

    monkeypatch.setattr(Survivors, "check", counted)
    shutil.copytree(EXAMPLE, tmp_path / "example")
    session = Session.open(tmp_path / "example").branch(tmp_path / "weak", "motion")
    with cpu_budget(1):  # the runs smoothed in this process, where the count is kept
        run_pipeline(session)
    motion = session.result("motion")
    assert any(failed), "no kept shortcut failed: the case shows nothing"
    bad = motion_collisions(session, motion)
    assert not bad, f"{len(bad)} colliding configurations, first: {bad[:3]}"
    rate = session.record_of("motion")["params"]["smooth_checks_per_s"]
    assert sum(p["smoothing_checks"] for p in motion.phases) <= rate * unsmoothed_duration(tmp_path / "bare")


class _Counted:
    """A stand-in validity that counts checks as the real ones bound them: a ramp's middle is one check, which passes;
    a curve's whole check could make 100 and makes 95, its screen makes 10, the rest over some spans 60 and 28 per share
    of the curve's time they cover (at most 88: never more than the whole); the whole check and the rest fail on the
    shortcuts `bad(curve)` names, so some shortcuts kept on their screen are refused."""

    def __init__(self, bad):
        self.checks, self.bad = 0, bad

    def state_valid(self, q) -> bool:
        self.checks += 1
        return True

    def curve_checks(self, curve) -> int:
        return 100

    def curve_valid(self, curve, ends=True, screen=False, spans=None) -> bool:
        if screen:
            self.checks += 10
            return True
        if spans is None:  # checked whole
            self.checks += 95
            return not self.bad(curve)
        self.checks += 60 + int(np.ceil(28 * sum(b - a for a, b in spans) / curve.duration))
        return not self.bad(curve)


def _replayed(run):
    """The attempts of a smoothing that replayed an outcome of the one before (the same object, not made anew)."""
    return (out for out, before in zip(run.log, run.record) if out is before)


def _one_run(monkeypatch, validity):
    """A smoother of three joints whose every ramp is checked by `validity`, and one run of a random polyline."""
    from types import SimpleNamespace

    from planner.motion.smoothing import Smoother, _Run

    monkeypatch.setattr(_Run, "validities", lambda self, t1, t2, moves: (validity,))
    robot = SimpleNamespace(nq=3, hand_idx={"right": np.array([], int)}, spec=SimpleNamespace(arm_names=["right"]))
    smoother = Smoother(SimpleNamespace(robot=robot), np.ones(3), np.full(3, 2.0), 0.02, 0.0, 0.0, 0)
    path = np.cumsum(np.random.default_rng(3).normal(0, 1, (12, 3)), axis=0)
    situation = SimpleNamespace(touching=(), support=(), holder=None, pose=np.eye(4))
    return smoother, [SimpleNamespace(phase=0, part="transit", path=path, situation=situation)]


def test_a_ramp_whose_middle_collides_is_refused_after_that_one_check(monkeypatch):
    """A ramp's middle (half its duration, a configuration the ramp passes through) is checked before its curve's checks
    are planned: where it collides, the attempt is refused after that single check, no curve check is planned or made,
    and the run stays timed rest to rest at every vertex."""
    from planner.motion.smoothing import _Run

    class Middle:
        checks = 0
        middles: list = []

        def state_valid(self, q) -> bool:
            self.checks += 1
            self.middles.append(np.array(q))
            return False

        def curve_checks(self, curve) -> int:
            raise AssertionError("a curve's checks were planned past its colliding middle")

        def curve_valid(self, *args, **kwargs) -> bool:
            raise AssertionError("a curve was checked past its colliding middle")

    validity = Middle()
    smoother, pieces = _one_run(monkeypatch, validity)
    tried = []
    attempt = _Run._try

    def recorded(self, t1, t2, known=None):  # the ramp each attempt stands for, made alone by ramps.ramp
        (qa, qb), (va, vb) = self.traj.states(np.array([t1, t2]))
        out = ramp(qa, va, qb, vb, self.smoother.vmax, self.smoother.amax, t2 - t1 - self.smoother.min_gain)
        if out is not None and t2 - t1 > self.smoother.min_gain:
            tried.append(out)
        return attempt(self, t1, t2, known)

    monkeypatch.setattr(_Run, "_try", recorded)
    run = smoother.smooth(pieces, np.random.default_rng(7), 400, 4000)
    assert run.shortcuts == 0 and 0 < run.checks == validity.checks == len(tried)
    for shortcut, middle in zip(tried, validity.middles):  # each check was of its ramp's middle
        assert np.allclose(shortcut.positions(np.array([shortcut.duration / 2]))[0], middle)
    assert np.allclose(run.trajectory.q, rest_to_rest(pieces[0].path, np.ones(3), np.full(3, 2.0)).q)


@pytest.mark.parametrize("budget", [300, 700, 1500, 4000])
def test_the_checks_held_back_keep_every_smoothing_within_its_budget(budget, monkeypatch):
    """A run of one random polyline smoothed with the stand-in validity (a shortcut in five fails the rest of its
    checks): every check made, screens, the rest of the kept shortcuts' checks (made early when what is held back
    leaves too little), and those of the smoothings taken again after a refusal, stays within the budget; what the
    result keeps of each shortcut passed; one seed, one result."""
    from planner.motion.smoothing import _Run

    def bad(curve) -> bool:
        return int(curve.duration * 1e6) % 5 == 0

    validity = _Counted(bad)
    smoother, pieces = _one_run(monkeypatch, validity)
    made = []
    init = _Run.__init__

    def recorded(self, *args, **kwargs):
        init(self, *args, **kwargs)
        made.append(self)

    monkeypatch.setattr(_Run, "__init__", recorded)
    results = []
    for _ in range(2):
        before, made[:] = validity.checks, []
        run = smoother.smooth(pieces, np.random.default_rng(7), 400, budget)
        assert run.checks == validity.checks - before <= budget
        last = made[-1].survivors
        assert not any(bad(last.kept[p.seq].shortcut) for p in last.parts), "a failing shortcut is in the result"
        results.append((run, len(made)))
    (run, smoothings), (again, _) = results
    assert np.array_equal(run.trajectory.q, again.trajectory.q) and run.checks == again.checks
    # per pass: the shortcuts kept are the run's, the seconds they saved its time rest to rest less its duration, and
    # every attempt made anew is counted once (the replays of a smoothing taken again are not)
    assert sum(run.kept) == run.shortcuts and all(0 <= k <= a for k, a in zip(run.kept, run.attempts))
    assert abs(sum(run.saved) - (smoother.rest_to_rest(pieces) - run.trajectory.duration)) < 1e-9
    assert sum(run.attempts) == sum(len(r.log) - sum(1 for _ in _replayed(r)) for r in made)
    if budget >= 1500:
        assert smoothings > 1, "no kept shortcut was refused: the case shows nothing"
        assert run.shortcuts > 0 and run.trajectory.duration < smoother.rest_to_rest(pieces)
