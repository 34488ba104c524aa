"""The motion step's parameters and result: one sampled trajectory from q_initial to q_final, and Table I per phase."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.core.bounds import bounded, described
from planner.core.results import array
from planner.motion.phase import Phase

PHASES = tuple(phase.title for phase in Phase)[:4]  # a handover's Table I rows (the paper's), in the order of the stored integers
TABLE_PHASES = tuple(phase.title for phase in Phase)  # a table handover's or a same-hand regrasp's: those and Set down, Regrasp
PLANNERS = ("roadmap", "rrt")
STRATEGIES = {"auto": ("handover", "table", "regrasp"), "handover": ("handover",), "table": ("table",),
              "regrasp": ("regrasp",)}  # strategy -> those the regrasp graph may use
PHASE_SECONDS = ("planning", "validating", "reconnecting", "shortcutting", "contact")  # the step's stage seconds per phase,
# in this order, then one for timing and sampling


@dataclass(frozen=True)
class MotionParams:
    planner: str = described("roadmap", "roadmap: Super Graph, lazy revalidation, RRT reconnection; rrt: RRTConnect alone (baseline)",
                             PLANNERS)
    pregrasp_distance: float = bounded(0.06, 0.0, 0.5, "m", "a hand backs off this far along its approach direction before it approaches")
    lift: float = bounded(0.06, 0.001, 0.5, "m", "the object is lifted off and set down by this much (or twice), vertically where free")
    lift_candidates: int = bounded(8, 1, 100, "motions", "lift and set-down motions tried, freest first")
    preshape: float = bounded(1.0, 0.0, 1.0, "(fraction)", "fingers before an approach: this fraction of the way from the grasp to open")
    release: float = bounded(0.6, 0.0, 1.0, "(fraction)", "fingers letting go: this fraction of the way open before the hand retreats")
    straight_steps: int = bounded(4, 1, 100, "waypoints", "IK waypoints on each straight hand motion")
    max_velocity: float = bounded(1.0, 0.01, 20.0, "rad/s", "joint speeds are capped here (and by the robot's own limits)")
    max_acceleration: float = bounded(2.0, 0.01, 100.0, "rad/s^2", "joint accelerations are capped here")
    rate: float = bounded(30.0, 1.0, 1000.0, "Hz", "the trajectory's sampling rate")
    connections: int = bounded(4, 1, 100, "edges", "transit: edges joining each end to the graph, nearest valid nodes first")
    max_connections: int = bounded(48, 1, 1000, "nodes", "transit: nearest nodes tried for those edges")
    max_join: float = bounded(2.0, 0.0, 100.0, "rad", "transit: nodes farther from an end are not tried (RRTConnect from it)")
    max_searches: int = bounded(60, 1, 10000, "searches", "transit: graph searches after invalidations before reconnecting")
    max_reconnections: int = bounded(2, 0, 100, "calls", "transit: RRTConnect calls per query (then the next candidate end)")
    phase_reconnections: int = bounded(4, 0, 1000, "calls", "transit: RRTConnect calls per phase (then its queries search the graph only)")
    reconnect_motions: int = bounded(1000, 1, 1000000, "motion checks", "a budget of one RRTConnect reconnection (counts: any "
                                     "machine; rrt_motions from an end no graph edge joins)")
    away_motions: int = bounded(400, 1, 1000000, "motion checks", "a budget of the picking arm's move away alone, per target "
                                "(either planner)")
    patient_sequences: int = bounded(4, 0, 1000, "sequences", "when none moved: the first that failed at a transit, again with "
                                     "rrt_motions per reconnection")
    rrt_motions: int = bounded(20000, 1, 1000000, "motion checks", "a budget of one RRTConnect query of the baseline planner 'rrt'")
    rrt_step: float = bounded(0.5, 0.01, 10.0, "rad", "RRTConnect's range (longest extension, joint-space distance)")
    shortcut_attempts: int = bounded(30, 0, 10000, "shortcuts", "random straight shortcuts per transit, after the greedy ones")
    shortcut_min_gain: float = bounded(0.1, 0.0, 10.0, "rad", "a straight shortcut shortening the path by less is not checked")
    graph_shortcut_length: float = bounded(3.0, 0.0, 100.0, "rad",
                                           "roadmap: a graph path's shortcuts longer than this are not tried (but over an RRT detour)")
    smooth_attempts_per_s: float = bounded(10.0, 0.0, 100000.0, "shortcuts/s", "random parabolic shortcuts drawn for a run, per "
                                           "second it could save (its time rest to rest less its ends' least)")
    smooth_checks_per_s: float = bounded(1000.0, 0.0, 10000000.0, "checks/s", "collision checks a run's smoothing may make, per "
                                         "second it could save")
    smooth_min_gain: float = bounded(0.02, 0.0, 10.0, "s", "a parabolic shortcut saving less time is not checked")
    goal_nodes: int = bounded(16, 1, 1000, "nodes", "transit: an end the graph cannot reach is reconnected to this many nodes")
    max_double_grasps: int = bounded(20, 1, 1000, "double grasps", "tried, best first")
    transit_env_padding: float = bounded(0.03, 0.001, 0.2, "m", "transit checks: obstacles count as hit this close (lowered per end)")
    transit_self_padding: float = bounded(0.015, 0.001, 0.2, "m", "transit checks: robot-robot and robot-object pairs likewise")
    contact_env_padding: float = bounded(0.008, 0.001, 0.05, "m", "contact motions keep obstacles this far at checks")
    contact_env_clearance: float = bounded(0.004, 0.0, 0.05, "m", "... and this far between checks")
    contact_penetration: float = bounded(0.001, 1e-5, 0.01, "m", "hand-object pairs touch at most this deep between checks (0 at them)")
    contact_coarse: int = bounded(3, 1, 100, "(factor)", "contact checks at every k-th configuration with k-times margins first (1: dense)")
    strategy: str = described("auto", "handover: in the air; table: set down for the other hand; regrasp: retaken by the same "
                              "hand; auto: handover first", tuple(STRATEGIES))
    contact_seconds: float = bounded(1.0, 0.0, 60.0, "s", "regrasp graph: each contact motion's estimated time (transits: joint "
                                     "distance over max_velocity)")
    regrasp_grasps: int = bounded(8, 1, 1000, "grasps", "table, regrasp: each hand's grasps tried at a placement, best scored first")
    table_placements: int = bounded(24, 1, 1000, "placements", "table, regrasp: intermediate placements the arms reach tried, best first")
    table_candidates: int = bounded(16, 1, 1000, "motions", "table, regrasp: (placement, pick grasp, place grasp) motions tried, each")

    def problem(self) -> str:
        """What is wrong with the values, naming the parameter ('' when nothing): checked before the step runs."""
        if self.planner not in PLANNERS:
            return f"planner must be one of {', '.join(PLANNERS)}, got '{self.planner}'"
        if self.strategy not in STRATEGIES:
            return f"strategy must be one of {', '.join(STRATEGIES)}, got '{self.strategy}'"
        if self.contact_env_clearance >= self.contact_env_padding:
            return (f"contact_env_clearance must be below contact_env_padding ({self.contact_env_padding:g} m): a padding is checked "
                    f"so that the clearance holds between checks, got {self.contact_env_clearance:g} m")
        return ""


@dataclass(frozen=True)
class Motion:
    """A trajectory sampled at `rate`: time, configuration, phase (an index into `phase_names`), the object's world
    pose, which arm holds it (-1: none) and which arm's hand works at the object (-1: none), each wrist's position, and
the names of q's columns;
    `keyframes` are the samples at q_initial, q_grasp, q_exch, q_place and q_final (a direct transfer, one arm carrying
    the object, has no exchange: Carry takes it to above the placement, and its q_exch keyframe is q_place's; in a table
    handover q_exch is where the placing hand has closed on the object at the intermediate placement). `phases`
    holds Table I's counts per phase (seconds are in the session record)."""

    planner: str
    double_grasp: int  # rank of the double grasp used (-1 when none worked)
    tried: list  # per double grasp tried, best first: '' if used, else why it failed
    phases: list  # per phase: nodes added planning / validating, edges invalidated, RRT calls, searches, checks of transits
    # and their pair tests (all, RRTConnect's, the shortcuts'), checks of smoothing, path length and straight distance, its
    # transits' length and straight distance, duration
    arms: list  # arm names, the order of `holder` and `wrists`
    resolution: dict  # the transit and contact profiles
    stages: list
    failure: str
    t: np.ndarray = array("float64", ("n",))
    q: np.ndarray = array("float64", ("n", "nq"))
    phase: np.ndarray = array("int8", ("n",))
    object_pose: np.ndarray = array("float64", ("n", 4, 4))
    holder: np.ndarray = array("int8", ("n",))
    active: np.ndarray = array("int8", ("n",))  # the arm whose hand works at the object (approach, closing, lift, ...), -1
    wrists: np.ndarray = array("float64", ("n", 2, 3))
    keyframes: np.ndarray = array("int64", (5,))
    joint_names: tuple = ()  # the robot's joints in q's column order (absent from sessions older than it: see joint_names_of)
    phase_names: tuple = PHASES  # what `phase` and the rows of `phases` index (a table handover's are TABLE_PHASES)
    strategy: str = "handover"  # the one that moved: 'handover' (a double grasp, or a direct transfer), 'table' or 'regrasp'
    alternatives: tuple = ()  # the other strategies (all of them when none worked): {"strategy", "failure": the stage that
    # removed it}
    intermediate: tuple = ()  # a table handover's or regrasp's intermediate placement: the object's pose, 4 rows of 4 (empty: none)
    sequence: tuple = ()  # the regrasp graph's sequence that moved: per transition {"kind", "hand", "grasps", "grasp", "at",
    # "seconds" (estimated), "double_grasp" (a handover's)}; empty in sessions older than it
    qd: np.ndarray = array("float64", ("n", "nq"), optional=True)  # joint velocities at the samples, read from the timed
    # trajectory (rad/s); empty in sessions older than it
    qdd: np.ndarray = array("float64", ("n", "nq"), optional=True)  # joint accelerations there (rad/s^2, constant over each
    # parabolic piece: at a breakpoint the next piece's; where the robot comes to rest, the last piece's); empty likewise

    @property
    def duration(self) -> float:
        return float(self.t[-1]) if len(self.t) else 0.0

    def phase_name(self, phase: int) -> str:
        """The name of a stored phase integer ('phase 7' for one a session names no phase for: sessions are untrusted)."""
        return str(self.phase_names[phase]) if 0 <= phase < len(self.phase_names) else f"phase {phase}"

    def stats(self) -> dict:
        return {"planner": self.planner, "strategy": self.strategy, "double_grasp": self.double_grasp, "samples": int(len(self.t)),
                "duration": round(self.duration, 3),
                "path_length": round(sum(p["path_length"] for p in self.phases), 3) if self.phases else 0.0,
                **({"failure": self.failure} if self.failure else {})}
