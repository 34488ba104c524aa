"""The motion does not depend on how many processes plan it: with one CPU the transits and the smoothing's runs are
planned in the process, with two in forked workers, and the motion, and every count of Table I, are the same. What a
worker measured or checked and the process did not must leave no trace (a distance solver's state did: the fitted
paddings, and the smoothing's checks, differed)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from planner.core.forked import cpu_budget
from planner.core.session import Session
from planner.core.steps import step_seed
from planner.handover.grasp_configs import GraspConfigParams
from planner.motion import plan_motion
from planner.motion.result import MotionParams

EXAMPLE = Path(__file__).resolve().parent.parent / "sessions" / "default-example"


def sampled_runs(monkeypatch) -> list:
    """The (pieces, runs smoothed in the transit workers) each motion step hands to its sampling, recorded from now on."""
    import planner.motion.step

    sampled = []
    sample = planner.motion.step.sample

    def kept(pieces, smoother, dt, made):
        sampled.append((pieces, made))
        return sample(pieces, smoother, dt, made)

    monkeypatch.setattr(planner.motion.step, "sample", kept)
    return sampled


def transit_runs(pieces) -> list:
    """The run_key of each run of `pieces` that holds a transit."""
    from planner.motion.runs import run_key, runs

    return [run_key(run) for run in runs(pieces) if any(p.part == "transit" for p in run)]


@pytest.mark.slow
def test_one_process_or_forked_workers_plan_the_same_motion():
    s = Session.open(EXAMPLE)
    made = []
    for cpus in (1, 2):
        with cpu_budget(cpus):
            motion, _ = plan_motion(s.scene, s.result("pick_grasps"), s.result("place_grasps"), s.result("double_grasps"),
                                    s.result("roadmap"), MotionParams(strategy="handover"),
                                    np.random.default_rng(step_seed(0, "motion")),
                                    configs=(s.result("grasp_configs"), GraspConfigParams()))
        made.append(motion)
    inline, forked = made
    assert inline.phases == forked.phases  # Table I's counts: nodes, searches, checks, pair tests, smoothing checks
    assert np.array_equal(inline.t, forked.t) and np.array_equal(inline.q, forked.q)


@pytest.mark.slow
def test_the_runs_are_smoothed_alike_in_the_transit_workers_or_after_them(monkeypatch):
    """A run is smoothed in the worker of the transit stage that completes it, or, where none did, after the transits:
    its random stream comes from the run itself, so the motion is the same either way; and the workers did smooth
    every run that holds a transit (the layout the handover gives its jobs is right)."""
    from planner.motion.smoothing import Smoother

    s = Session.open(EXAMPLE)
    sampled = sampled_runs(monkeypatch)

    def plan():
        with cpu_budget(2):
            motion, _ = plan_motion(s.scene, s.result("pick_grasps"), s.result("place_grasps"), s.result("double_grasps"),
                                    s.result("roadmap"), MotionParams(strategy="handover"),
                                    np.random.default_rng(step_seed(0, "motion")),
                                    configs=(s.result("grasp_configs"), GraspConfigParams()))
        return motion, sampled[-1]

    there, (pieces, made) = plan()
    transits = transit_runs(pieces)
    assert len(transits) == 4 and set(transits) == set(made)  # Grasp's, Carry's, Place's and Rest's runs
    monkeypatch.setattr(Smoother, "smooth_runs", lambda self, *args: ({}, 0.0))
    after, (_, made) = plan()
    assert not made
    assert there.phases == after.phases
    assert np.array_equal(there.t, after.t) and np.array_equal(there.q, after.q)


def test_a_job_finishes_only_while_no_job_has_failed():
    """The transit jobs finish in their workers (the smoothing of their runs) only while every job before has made its
    pieces: once one failed, the double grasp is lost and so would be what the others finish. In one process, in
    order: a job after a failure does not finish, a job before it does, and a failed job never does."""
    from types import SimpleNamespace

    from planner.motion.phase import Phase
    from planner.motion.piece import PieceFailed
    from planner.motion.runner import run_transits
    from planner.motion.transit import TransitStats

    def fails(stage):
        raise PieceFailed(Phase.GRASP, "transit", "no way")

    def moves(stage):
        return ["piece"]

    def run(jobs):
        finished = []
        stats = [TransitStats() for _ in Phase]
        with cpu_budget(1):
            results = run_transits([(Phase.GRASP, job) for job in jobs], lambda *a: SimpleNamespace(stats=a[3]),
                                   SimpleNamespace(copy=lambda: None), np.random.default_rng(0), stats, None,
                                   lambda i, pieces: finished.append(i) or i)
        return finished, [done for _, done in results]

    assert run([moves, fails, moves]) == ([0], [0, None, None])
    assert run([moves, moves]) == ([0, 1], [0, 1])
