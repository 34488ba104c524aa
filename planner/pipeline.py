"""The pipeline: every step, in order. A new step plugs in by adding its STEP here."""
from __future__ import annotations

from planner import motion, roadmap
from planner.core.errors import RegraspError
from planner.core.steps import Step
from planner.grasping import grasp_list as grasps
from planner.handover import arms, double_grasps, exchange, grasp_configs
from planner.regrasp import placements

PIPELINE: tuple[Step, ...] = (arms.STEP, grasps.PICK_STEP, grasps.PLACE_STEP, grasp_configs.STEP, exchange.STEP, double_grasps.STEP,
                              roadmap.STEP, placements.STEP, motion.STEP)


def canonical(name: str) -> str:
    """Step names accept hyphens for underscores (`--until double-grasps`)."""
    return name.replace("-", "_")


def step_named(name: str) -> Step:
    name = canonical(name)
    for step in PIPELINE:
        if step.name == name:
            return step
    raise RegraspError(f"no step '{name}' (steps: {', '.join(s.name for s in PIPELINE)})")


def steps_until(until: str | None) -> tuple[Step, ...]:
    """The steps up to and including `until` (all of them when None)."""
    if until is None:
        return PIPELINE
    names = [s.name for s in PIPELINE]
    until = canonical(until)
    if until not in names:
        raise RegraspError(f"no step '{until}' (steps: {', '.join(names)})")
    return PIPELINE[: names.index(until) + 1]
