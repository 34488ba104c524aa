"""Online motion (paper V-B), composed like OMPL: a space, a validity per situation of the object, planners over them."""
from planner.motion.result import PHASE_SECONDS, PHASES, Motion, MotionParams
from planner.motion.step import STEP, plan_motion

__all__ = ["PHASE_SECONDS", "PHASES", "Motion", "MotionParams", "STEP", "plan_motion"]
