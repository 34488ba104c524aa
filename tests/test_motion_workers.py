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
