"""The one runner of the transits: once every contact motion is made, the phases' transits are independent and run at
once in forked workers (one per core), on the graph as with RRTConnect alone: a worker pays for the pages it writes,
but on two cores less than the second core gives (docs/benchmarks.md).

Each job gets its own transit stage: a random stream seeded from the plan's (drawn in the order of the jobs), its
own copy of the graph and its own figures, so the result does not depend on how many jobs run at once. Their
figures join their phases' afterwards, with the seconds the contact stages spent inside the jobs (trying a next
candidate end where a transit failed). A job that made its pieces may finish in its worker (the smoothing of the runs
they complete, with the checks its transits made ready), unless a job has failed by then: what the finish makes must
not depend on where or whether it was made (the smoothing's streams come from the runs, not the order).
"""
from __future__ import annotations

import ctypes
import dataclasses
import multiprocessing
from collections.abc import Callable
from typing import Any

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
Finish = Callable[[int, list[Piece]], Any]  # a job's index and its pieces


def run_transits(jobs: list[Job], make_stage: StageMaker, graph: MotionGraph, rng: np.random.Generator,
                 stats: list[TransitStats], weights: JointSpace | None, finish: Finish | None = None
                 ) -> list[tuple[list[Piece] | PieceFailed, Any]]:
    """(the pieces of each (phase, job) or how it failed, what `finish` made of its pieces: None where it failed, without
    `finish`, or where a job had failed before it finished), in the order given; run in that order in forked workers.
    `stats`: the phases' figures, which the jobs' join; `weights`: the space whose edge lengths every graph search weighs
    by, computed once here, before the workers inherit the graph (None: the jobs search no graph)."""
    seeds = rng.integers(2**63, size=len(jobs))
    failed = multiprocessing.RawValue(ctypes.c_bool, False)  # shared with the forked workers
    if weights is not None:
        graph.weights(weights)
    contact_before = [s.seconds_contact for s in stats]

    def run(i: int) -> tuple[list[Piece] | tuple[Phase, str, str], TransitStats, list[float], Any]:
        phase, job = jobs[i]
        before = [s.seconds_contact for s in stats]
        stage = make_stage(phase, graph.copy(), np.random.default_rng(seeds[i]), TransitStats())
        try:
            out: list[Piece] | tuple[Phase, str, str] = job(stage)
        except PieceFailed as exc:
            out = (exc.phase, exc.part, exc.why)
            failed.value = True  # the other jobs' finishing would be lost: this double grasp has failed
        spent = [s.seconds_contact - b for s, b in zip(stats, before)]
        done = None if finish is None or isinstance(out, tuple) or failed.value else finish(i, out)
        return out, stage.stats, spent, done

    results = forked_map(run, range(len(jobs)))
    for k, s in enumerate(stats):  # inline, the jobs' contact seconds are there already: counted once either way
        s.seconds_contact = contact_before[k] + sum(spent[k] for _, _, spent, _ in results)
    for (phase, _), (_, job_stats, _, _) in zip(jobs, results):
        for f in dataclasses.fields(job_stats):
            setattr(stats[phase], f.name, getattr(stats[phase], f.name) + getattr(job_stats, f.name))
    return [(PieceFailed(*value) if isinstance(value, tuple) else value, done) for value, _, _, done in results]
