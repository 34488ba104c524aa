"""`regrasp bench motion`: the motion step with the Super Graph (ours) and with RRTConnect alone, Table I for each, and
where their transits' time and narrow-phase work go."""
from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from planner.cli.bench import ONLINE_STEPS, bench_collision
from planner.core.errors import RegraspError
from planner.model.task import Scene


@dataclass(frozen=True)
class MotionBench:
    """The motion step over seeds with the Super Graph (ours) and with RRTConnect alone (the baseline), Table I for each."""

    seeds: list
    runs: dict  # planner -> per seed: {"seconds", "success", "double_grasp", "phases": Table I rows, "phase_seconds"}
    check_us: tuple[float, float] = (float("nan"), float("nan"))  # a full check's median µs before and after the runs
    repeat: int = 1  # runs per seed and planner, the fastest kept
    roadmaps: int = 1  # ours ran on the roadmaps of session seeds 0..roadmaps-1 (RRTConnect alone once per seed)

    def to_dict(self) -> dict:
        ours, rrt = (self.summary(p) for p in ("roadmap", "rrt"))
        return {"seeds": self.seeds, "repeat": self.repeat, "roadmaps": self.roadmaps, "per_roadmap": self.per_roadmap(),
                "ours_total_seconds_median": ours["seconds"], "rrt_total_seconds_median": rrt["seconds"],
                "speedup": rrt["seconds"] / ours["seconds"] if ours["seconds"] > 0 else None,
                "ours_transit_checks_median": ours["transit_checks"], "rrt_transit_checks_median": rrt["transit_checks"],
                "check_ratio": rrt["transit_checks"] / ours["transit_checks"] if ours["transit_checks"] > 0 else None,
                "ours_transit_seconds_median": ours["transit_seconds"], "rrt_transit_seconds_median": rrt["transit_seconds"],
                "transit_speedup": self.transit_speedup(),
                "ours_pair_tests_median": ours["pair_tests"], "rrt_pair_tests_median": rrt["pair_tests"],
                "pair_test_ratio": rrt["pair_tests"] / ours["pair_tests"] if ours["pair_tests"] > 0 else None,
                "ours_pair_tests_by_part": ours["pair_parts"], "rrt_pair_tests_by_part": rrt["pair_parts"],
                "pair_test_ratio_bound": rrt["pair_tests"] / ours["unanswered"] if ours["unanswered"] > 0 else None,
                "speedup_bound": (rrt["seconds"] / ours["untransit_seconds"] if ours["untransit_seconds"] > 0 else None),
                **self.totals(), **self.by_joining(),
                "ours_success": ours["success"], "rrt_success": rrt["success"],
                "ours_duration_median": ours["duration"], "rrt_duration_median": rrt["duration"],
                "full_check_us_before": self.check_us[0], "full_check_us_after": self.check_us[1],
                "per_seed": self.per_seed(), "phases": {"ours": ours["phases"], "rrt": rrt["phases"]}, "runs": self.runs}

    def summary(self, planner: str) -> dict:
        """Medians over the seeds: total seconds, success fraction, and per phase Table I's figures."""
        from planner.motion import PHASE_SECONDS, PHASES

        runs, per = self.runs[planner], len(PHASE_SECONDS)
        parts = [_pair_parts(r) for r in runs if r["phases"]]  # each run's transit pair tests by part
        phases = []
        for i, name in enumerate(PHASES):
            ok = [r for r in runs if r["phases_done"] > i]
            rows = [r["phases"][i] for r in runs if r["phases"]]
            phases.append({"phase": name, "success": len(ok) / len(runs),
                           "nodes_planning": median([r["nodes_planning"] for r in rows]),
                           "nodes_validating": median([r["nodes_validating"] for r in rows]),
                           "seconds_planning": median([r["phase_seconds"][per * i] for r in runs if r["phases"]]),
                           "seconds_validating": median([r["phase_seconds"][per * i + 1] for r in runs if r["phases"]]),
                           "seconds_reconnecting": median([r["phase_seconds"][per * i + 2] for r in runs if r["phases"]]),
                           "seconds": median([sum(r["phase_seconds"][per * i: per * (i + 1)]) for r in runs if r["phases"]]),
                           "edges_invalidated": median([r["edges_invalidated"] for r in rows]),
                           "ends_alone": median([r.get("ends_alone", 0) for r in rows]),
                           "rrt_calls": median([r["rrt_calls"] for r in rows]),
                           "transit_checks": median([r["transit_checks"] for r in rows]),
                           "pair_tests": median([r.get("transit_pair_tests", 0) for r in rows]),
                           "smoothing_checks": median([r.get("smoothing_checks", 0) for r in rows]),
                           "path_length": median([r["path_length"] for r in rows]),
                           "straight_distance": median([r.get("straight_distance", np.nan) for r in rows]),
                           "duration": median([r["duration"] for r in rows])})
        return {"seconds": median([r["seconds"] for r in runs]), "success": sum(r["success"] for r in runs) / len(runs),
                "transit_seconds": median([_transit_seconds(r) for r in runs if r["phases"]]),
                "pair_tests": median([_pair_tests(r) for r in runs if r["phases"]]),
                "duration": median([sum(p["duration"] for p in r["phases"]) for r in runs if r["success"]]),
                "transit_checks": median([_transit_checks(r) for r in runs if r["phases"]]),
                "pair_parts": {k: median([p[k] for p in parts]) for k in PAIR_PARTS},
                "unanswered": median([sum(p[k] for k in UNANSWERED) for p in parts]),
                "untransit_seconds": median([r["seconds"] - _transit_seconds(r) for r in runs if r["phases"]]),
                "phases": phases, "where": self.where(planner)}

    def transit_speedup(self) -> float | None:
        """The median over ours' runs (seeds, on each roadmap) of RRTConnect's transit seconds on the run's seed over ours
        (a ratio per run: the two ran in the same minutes, so a busy minute slows both)."""
        ratios = [_transit_seconds(b) / _transit_seconds(a) for a, b in self._pairs()
                  if a["phases"] and b["phases"] and _transit_seconds(a) > 0]
        return median(ratios) if ratios else None

    def totals(self) -> dict:
        """Sums over ours' runs and RRTConnect's run of the same seed (once per run of ours): transit pair tests and the
        step's seconds, and their ratios. A median hides the seeds where one planner spends most (double grasps given up
        after whole queries); a sum shows them."""
        pairs = self._pairs()
        ours, rrt = sum(_pair_tests(a) for a, _ in pairs), sum(_pair_tests(b) for _, b in pairs)
        ours_s, rrt_s = sum(a["seconds"] for a, _ in pairs), sum(b["seconds"] for _, b in pairs)
        return {"ours_pair_tests_total": ours, "rrt_pair_tests_total": rrt, "pair_test_ratio_total": _ratio(rrt, ours),
                "ours_seconds_total": ours_s, "rrt_seconds_total": rrt_s, "speedup_total": _ratio(rrt_s, ours_s)}

    def by_joining(self) -> dict:
        """Where the roadmap acts: the phases of ours' runs split by whether the graph joined every query end (none
        alone), each beside RRTConnect's same phase on the same seed (the same double grasp only), summed: their transit
        pair tests less the arm moved away (the same work for either), and how many phases; an end no edge joins makes
        its query RRTConnect's from there, so only the joined phases show what the roadmap saves."""
        out = {}
        for key, alone in (("joined", False), ("alone", True)):
            rows = [(p, q) for a, b in self._pairs() if a["double_grasp"] == b["double_grasp"]
                    for p, q in zip(a["phases"], b["phases"]) if (p.get("ends_alone", 0) > 0) == alone]
            ours, rrt = (sum(r.get("transit_pair_tests", 0) - r.get("transit_pair_tests_away", 0) for r in side)
                         for side in zip(*rows)) if rows else (0, 0)
            out.update({f"phases_{key}": len(rows), f"ours_pair_tests_{key}": ours, f"rrt_pair_tests_{key}": rrt,
                        f"pair_test_ratio_{key}": _ratio(rrt, ours) if ours > 0 else None})  # JSON has no NaN
        return out

    def _pairs(self) -> list[tuple[dict, dict]]:
        """(ours, RRTConnect's) of each run of ours, with RRTConnect's run of the same seed."""
        rrt = {b["seed"]: b for b in self.runs["rrt"]}
        return [(a, rrt[a["seed"]]) for a in self.runs["roadmap"] if a["seed"] in rrt]

    def per_seed(self) -> list[dict]:
        """Per run of ours (a seed, on a roadmap) and RRTConnect's of the same seed: the step's seconds, its transits'
        seconds and their pair tests, for each."""
        return [{"seed": a["seed"], "roadmap": a.get("roadmap", 0), "ours_seconds": a["seconds"], "rrt_seconds": b["seconds"],
                 "ours_transit_seconds": _transit_seconds(a), "rrt_transit_seconds": _transit_seconds(b),
                 "ours_pair_tests": _pair_tests(a), "rrt_pair_tests": _pair_tests(b),
                 "ours_success": a["success"], "rrt_success": b["success"]}
                for a, b in self._pairs()]

    def per_roadmap(self) -> list[dict]:
        """Per roadmap, ours' medians over the seeds: pair tests, transit seconds, the motion's duration, and success."""
        out = []
        for r in range(self.roadmaps):
            runs = [a for a in self.runs["roadmap"] if a.get("roadmap", 0) == r]
            out.append({"roadmap": r, "pair_tests": median([_pair_tests(a) for a in runs if a["phases"]]),
                        "transit_seconds": median([_transit_seconds(a) for a in runs if a["phases"]]),
                        "duration": median([sum(p["duration"] for p in a["phases"]) for a in runs if a["success"]]),
                        "success": sum(a["success"] for a in runs) / len(runs) if runs else float("nan")})
        return out

    def where(self, planner: str) -> dict:
        """Medians over the seeds of the seconds spent in each kind of work, summed over the phases of the motion found
        ('other': the wall time minus the rest: the double grasps given up before it and setting up, less the time the
        phases' transits saved by running in parallel; the baseline's RRTConnect queries count as graph search)."""
        from planner.motion import PHASE_SECONDS

        kinds, per = ("graph search", "validation", "RRT", "shortcutting", "contact motions"), len(PHASE_SECONDS)
        rows = {k: [] for k in (*kinds, "timing and sampling", "other")}
        for r in self.runs[planner]:
            sec, n = r["phase_seconds"], len(r["phases"])
            if not sec or not n:
                continue
            for j, kind in enumerate(kinds):
                rows[kind].append(sum(sec[per * i + j] for i in range(n)))
            rows["timing and sampling"].append(sec[per * n])  # after it, the sequence search's stages (wall time, overlapping)
            rows["other"].append(r["seconds"] - sum(sec[: per * n + 1]))
        return {k: median(v) for k, v in rows.items()}

    def render(self) -> str:
        out = []
        for planner, title in (("roadmap", "ours: Super Graph, lazy revalidation, RRT reconnection"), ("rrt", "RRTConnect alone")):
            s = self.summary(planner)
            fastest = f" (the fastest of {self.repeat} runs each)" if self.repeat > 1 else ""
            on = f" x {self.roadmaps} roadmaps" if planner == "roadmap" and self.roadmaps > 1 else ""
            out += [f"{title}: median {s['seconds']:.2f} s over {len(self.seeds)} seeds{on}{fastest}, success {s['success']:.0%}, "
                    f"{s['transit_checks']:.0f} transit collision checks, motion {s['duration']:.2f} s long",
                    f"{'phase':<7}{'nodes plan':>11}{'s plan':>8}{'nodes val':>10}{'s val':>8}{'invalid':>8}{'alone':>6}{'RRT':>5}"
                    f"{'checks':>8}{'pairs':>9}{'smooth':>8}{'s total':>9}{'success':>8}{'length':>8}{'straight':>9}{'duration':>9}"]
            for r in s["phases"]:
                out.append(f"{r['phase']:<7}{r['nodes_planning']:>11.0f}{r['seconds_planning']:>8.2f}{r['nodes_validating']:>10.0f}"
                           f"{r['seconds_validating']:>8.2f}{r['edges_invalidated']:>8.0f}{r['ends_alone']:>6.0f}{r['rrt_calls']:>5.0f}{r['transit_checks']:>8.0f}"
                           f"{r['pair_tests']:>9.0f}{r['smoothing_checks']:>8.0f}{r['seconds']:>9.2f}{r['success']:>8.0%}{r['path_length']:>8.2f}"
                           f"{r['straight_distance']:>9.2f}{r['duration']:>9.2f}")
            out.append("where the time goes (median s): " + ", ".join(f"{k} {v:.2f}" for k, v in s["where"].items())
                       + " (other: the wall time minus the rest; below 0 when the phases' transits ran in parallel)")
            out.append("where the transits' pair tests go (median): " + ", ".join(f"{k} {v:.0f}" for k, v in s["pair_parts"].items()))
            out.append("")
        if self.roadmaps > 1:
            out.append(f"ours per roadmap (session seed's roadmap; medians over {len(self.seeds)} seeds):")
            out.append(f"{'roadmap':<8}{'pair tests':>11}{'transit s':>10}{'duration':>9}{'success':>8}")
            for row in self.per_roadmap():
                out.append(f"{row['roadmap']:<8}{row['pair_tests']:>11.0f}{row['transit_seconds']:>10.2f}{row['duration']:>9.2f}"
                           f"{row['success']:>8.0%}")
            out.append("")
        out += [f"{'seed':<6}{'roadmap':>8}{'transit s ours':>15}{'RRTConnect':>11}{'ratio':>7}{'pair tests ours':>16}{'RRTConnect':>11}"
                f"{'ratio':>7}{'step s ours':>12}{'RRTConnect':>11}"]
        for row in self.per_seed():
            out.append(f"{row['seed']:<6}{row['roadmap']:>8}{row['ours_transit_seconds']:>15.2f}{row['rrt_transit_seconds']:>11.2f}"
                       f"{_ratio(row['rrt_transit_seconds'], row['ours_transit_seconds']):>7.2f}{row['ours_pair_tests']:>16}"
                       f"{row['rrt_pair_tests']:>11}{_ratio(row['rrt_pair_tests'], row['ours_pair_tests']):>7.2f}"
                       f"{row['ours_seconds']:>12.2f}{row['rrt_seconds']:>11.2f}")
        out.append("")
        d = self.to_dict()
        out.append(f"speedup (RRTConnect median / ours): {d['speedup']:.2f}" if d["speedup"] else "speedup: n/a")
        if d["transit_speedup"]:
            out.append("transit speedup (median over ours' runs of RRTConnect's transit seconds, same seed, / ours): "
                       f"{d['transit_speedup']:.2f}")
        if d["pair_test_ratio"]:
            out.append(f"transit pair tests (RRTConnect median / ours): {d['pair_test_ratio']:.2f} (a count: the same on any machine)")
        if d["pair_test_ratio_bound"]:
            out.append(f"  at most {d['pair_test_ratio_bound']:.2f} were ours' ends, graph and RRT reconnections free (RRTConnect "
                       "median / the median of ours' shortcutting and arm moved away, which no roadmap answers)")
        if d["speedup_bound"]:
            out.append(f"  the step's speedup at most {d['speedup_bound']:.2f} were ours' transits free (RRTConnect median / "
                       "ours' step less its transits' seconds, median)")
        out.append(f"summed over the runs (each of ours with RRTConnect's on its seed), ours / RRTConnect: transit pair tests "
                   f"{d['ours_pair_tests_total']:,} / {d['rrt_pair_tests_total']:,} (RRTConnect / ours {d['pair_test_ratio_total']:.2f}), "
                   f"step {d['ours_seconds_total']:.1f} / {d['rrt_seconds_total']:.1f} s ({d['speedup_total']:.2f}): a median hides "
                   "the seeds where one planner spends most")
        for key, what in (("joined", "whose every query end the graph joined"), ("alone", "with a query end no graph edge joins")):
            if d[f"pair_test_ratio_{key}"] is None:
                out.append(f"phases {what}: {d[f'phases_{key}']}")
                continue
            out.append(f"phases {what}: {d[f'phases_{key}']}, their transit pair tests less the arm moved away, ours / "
                       f"RRTConnect {d[f'ours_pair_tests_{key}']:,} / {d[f'rrt_pair_tests_{key}']:,} (RRTConnect / ours "
                       f"{d[f'pair_test_ratio_{key}']:.2f}; summed, the same double grasp on both sides)")
        if d["check_ratio"]:
            out.append(f"transit collision checks (RRTConnect median / ours): {d['check_ratio']:.2f} (a count: the same on any machine)")
        out.append(f"a full collision check (regrasp bench collision) took {self.check_us[0]:.0f} µs before the runs and "
                   f"{self.check_us[1]:.0f} µs after: the seconds above scale with it, the counts do not")
        return "\n".join(out)


TRANSIT_KINDS = 4  # of each phase's PHASE_SECONDS, the first are its transits' (searching, validating, RRT, shortcutting)


def _given_up(motion, seconds: list[float]) -> dict:
    """The transits of the sequences a run gave up before the one that moved: checks, pair tests, seconds (0 if none)."""
    from planner.motion.strategies import GIVEN_UP

    k = next((i for i, s in enumerate(motion.stages) if s["stage"] == GIVEN_UP), None)
    if k is None:
        return {"checks": 0, "pair_tests": 0, "seconds": 0.0}
    return {"checks": motion.stages[k]["checks"], "pair_tests": motion.stages[k]["count"], "seconds": seconds[k]}


def _transit_seconds(run: dict) -> float:
    """A run's seconds in its transits, summed over the phases and the sequences given up (their workers' seconds: the
    transits run in parallel)."""
    from planner.motion import PHASE_SECONDS

    per, sec = len(PHASE_SECONDS), run["phase_seconds"]
    moved = sum(sum(sec[per * i: per * i + TRANSIT_KINDS]) for i in range(len(run["phases"])))
    return float(moved + run.get("given_up", {}).get("seconds", 0.0))


PAIR_PARTS = ("ends and graph", "RRTConnect", "shortcutting", "arm away", "given up")
UNANSWERED = ("shortcutting", "arm away")  # parts no roadmap answers: ours pays them as RRTConnect alone does


def _pair_parts(run: dict) -> dict[str, int]:
    """A run's transit pair tests by part (PAIR_PARTS, summing to `_pair_tests`): the phases' ends, joining them to the
    graph and validating it (the baseline's ends alone); RRTConnect (the baseline's queries, ours' reconnections);
    shortcutting; the picking arm moved alone from the exchange, whole (RRTConnect and its shortcuts, for either
    planner; in records made before it was counted apart, in the two before); the transits of the sequences given up."""
    rrt = sum(p.get("transit_pair_tests_rrt", 0) for p in run["phases"])
    cut = sum(p.get("transit_pair_tests_shortcut", 0) for p in run["phases"])
    away = sum(p.get("transit_pair_tests_away", 0) for p in run["phases"])
    rest = sum(p.get("transit_pair_tests", 0) for p in run["phases"]) - rrt - cut - away
    return dict(zip(PAIR_PARTS, (int(rest), int(rrt), int(cut), int(away), int(run.get("given_up", {}).get("pair_tests", 0)))))


def _pair_tests(run: dict) -> int:
    """A run's narrow-phase pair tests in its transits, summed over the phases and the sequences given up (0 for
    records from before they were counted)."""
    return int(sum(p.get("transit_pair_tests", 0) for p in run["phases"]) + run.get("given_up", {}).get("pair_tests", 0))


def _transit_checks(run: dict) -> int:
    """A run's collision checks in its transits, summed over the phases and the sequences given up."""
    return int(sum(p["transit_checks"] for p in run["phases"]) + run.get("given_up", {}).get("checks", 0))


def _ratio(a: float, b: float) -> float:
    return a / b if b > 0 else float("nan")


def median(values: list) -> float:
    return float(np.median(values)) if values else float("nan")


CHECK_SAMPLES = 500  # configurations a motion benchmark times a full check at, before and after its runs


def bench_inputs(scene: Scene, folder, progress, params: dict, roadmaps: int = 1) -> tuple[dict, dict, list]:
    """(each step's parameters, the offline steps' results, the roadmaps of session seeds 0..roadmaps-1): the offline
    steps run once (seed 0, from the user cache when there), as a motion benchmark's seeds share them."""
    from planner.core.runner import run_pipeline
    from planner.core.session import Session
    from planner.pipeline import PIPELINE
    from planner.roadmap.step import roadmap_for, session_roadmap_seed

    made = {step.name: step.make_params(params.get(step.name)) for step in PIPELINE}
    base = Session.create(folder / "base", scene, 0)
    progress("offline steps: arms and grasp lists (from the user cache when computed before) ...")
    run_pipeline(base, until="place_grasps", params=params)  # the online steps run per seed, below
    offline = {name: base.result(name) for name in ("arms", "pick_grasps", "place_grasps")}
    graphs = []
    for r in range(roadmaps):
        progress(f"the roadmap of session seed {r} (from the user cache when built before) ...")
        graphs.append(roadmap_for(scene, made["roadmap"], session_roadmap_seed(r))[0])
    return made, offline, graphs


def seed_inputs(scene: Scene, made: dict, offline: dict, graph, seed: int) -> dict:
    """The results the motion step reads for an online seed: the offline ones, the roadmap and the online steps'."""
    from planner.core.steps import StepContext, step_seed
    from planner.pipeline import step_named

    results = {**offline, "roadmap": graph}
    for name in ONLINE_STEPS:
        step = step_named(name)
        ctx = StepContext(scene, {n: results[n] for n in step.needs}, {n: made[n] for n in step.needs},
                          made[name], np.random.default_rng(step_seed(seed, name)))
        results[name] = step.run(ctx).result
    return results


def timed_motion(scene: Scene, results: dict, made: dict, motion_params, seed: int, repeat: int = 1) -> tuple[float, object, list]:
    """(wall seconds, motion, its stages' seconds) of the fastest of `repeat` plans of the seed's motion (the same seed
    gives the same motion each time: only its time varies)."""
    from planner.core.steps import step_seed
    from planner.motion import plan_motion

    timed = []
    for _ in range(repeat):
        start = time.perf_counter()
        motion, seconds = plan_motion(scene, results["pick_grasps"], results["place_grasps"], results["double_grasps"],
                                      results["roadmap"], motion_params, np.random.default_rng(step_seed(seed, "motion")),
                                      configs=(results["grasp_configs"], made["grasp_configs"]))
        timed.append((time.perf_counter() - start, motion, seconds))
    return min(timed, key=lambda run: run[0])


def bench_motion(scene: Scene, seeds: int, folder, progress=print, repeat: int = 1, roadmaps: int = 1,
                 params: dict | None = None) -> MotionBench:
    """The offline steps once (seed 0, from the cache when there); per seed the online steps, then the motion planned with
    the Super Graph and with RRTConnect alone from the same double grasps (rank order and contact motions are shared),
    `repeat` times each, the fastest run kept (the same seed gives the same motion: only its time varies). `roadmaps` K:
    ours on the roadmaps sessions 0..K-1 build (one roadmap's seed moves ours' figures as much as a change may), RRTConnect
    alone once per seed (it uses no roadmap). `params`: step -> parameter overrides (`--set`), for every run."""
    from planner.motion import PHASES

    params = params or {}
    chosen = {"planner", "strategy"} & set(params.get("motion", {}))
    if chosen:
        raise RegraspError(f"--set: bench motion sets motion.{' and motion.'.join(sorted(chosen))} itself (it compares the planners "
                         "on the handover)")
    made, offline, graphs = bench_inputs(scene, folder, progress, params, roadmaps)
    runs: dict = {"roadmap": [], "rrt": []}
    before = bench_collision(scene, CHECK_SAMPLES).full_check_us_median
    for seed in range(seeds):
        results = seed_inputs(scene, made, offline, graphs[0], seed)
        for planner, r in [("roadmap", r) for r in range(roadmaps)] + [("rrt", None)]:
            elapsed, motion, seconds = timed_motion(scene, {**results, "roadmap": graphs[r or 0]}, made,
                                                    replace(made["motion"], planner=planner, strategy="handover"), seed, repeat)
            failed = next((why for why in motion.tried if why), "")
            done = len(PHASES) if not motion.failure else next(i for i, n in enumerate(PHASES) if failed.startswith(n))
            runs[planner].append({"seed": seed, "roadmap": r, "seconds": elapsed, "success": not motion.failure,
                                  "double_grasp": motion.double_grasp, "phases": motion.phases, "phase_seconds": seconds,
                                  "phases_done": done, "failure": motion.failure, "given_up": _given_up(motion, seconds)})
            on = f" (roadmap {r})" if roadmaps > 1 and r is not None else ""
            progress(f"seed {seed} {planner}{on}: {elapsed:.2f} s, {'ok' if not motion.failure else motion.failure[:120]}")
    return MotionBench(list(range(seeds)), runs, (before, bench_collision(scene, CHECK_SAMPLES).full_check_us_median), repeat, roadmaps)
