"""The one runner of the transits: once every contact motion is made, the phases' transits are independent and run at
once in forked workers (one per core), on the graph as with RRTConnect alone: a worker pays for the pages it writes,
but on two cores less than the second core gives (docs/benchmarks.md).

Each job gets its own transit stage: a random stream seeded from the plan's (drawn in the order of the jobs), its
own copy of the graph and its own figures, so the result does not depend on how many jobs run at once. Their
figures join their phases' afterwards, with the seconds the contact stages spent inside the jobs (trying a next
candidate end where a transit failed).
"""
from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from planner.core.forked import forked_map
from planner.motion.graph import MotionGraph
from planner.motion.phase import Phase
from planner.motion.piece import Piece, PieceFailed
from planner.motion.space import JointSpace
from planner.motion.transit import TransitStats
from planner.motion.transit_stage import TransitStage

Job = tuple[Phase, Callable[[TransitStage], list[Piece]]]  # a phase and what its stage makes
StageMaker = Callable[[Phase, MotionGraph, np.random.Generator, TransitStats], TransitStage]


def run_transits(jobs: list[Job], make_stage: StageMaker, graph: MotionGraph, rng: np.random.Generator,
                 stats: list[TransitStats], weights: JointSpace | None) -> list[list[Piece] | PieceFailed]:
    """The pieces of each (phase, job), or how it failed, in the order given; run in that order in forked workers.
    `stats`: the phases' figures, which the jobs' join; `weights`: the space whose edge lengths every graph search
    weighs by, computed once here, before the workers inherit the graph (None: the jobs search no graph)."""
    seeds = rng.integers(2**63, size=len(jobs))
    if weights is not None:
        graph.weights(weights)
    contact_before = [s.seconds_contact for s in stats]

    def run(i: int) -> tuple[list[Piece] | tuple[Phase, str, str], TransitStats, list[float]]:
        phase, job = jobs[i]
        before = [s.seconds_contact for s in stats]
        stage = make_stage(phase, graph.copy(), np.random.default_rng(seeds[i]), TransitStats())
        try:
            out: list[Piece] | tuple[Phase, str, str] = job(stage)
        except PieceFailed as exc:
            out = (exc.phase, exc.part, exc.why)
        return out, stage.stats, [s.seconds_contact - b for s, b in zip(stats, before)]

    results = forked_map(run, range(len(jobs)))
    for k, s in enumerate(stats):  # inline, the jobs' contact seconds are there already: counted once either way
        s.seconds_contact = contact_before[k] + sum(spent[k] for _, _, spent in results)
    for (phase, _), (_, job_stats, _) in zip(jobs, results):
        for f in dataclasses.fields(job_stats):
            setattr(stats[phase], f.name, getattr(stats[phase], f.name) + getattr(job_stats, f.name))
    return [PieceFailed(*value) if isinstance(value, tuple) else value for value, _, _ in results]
