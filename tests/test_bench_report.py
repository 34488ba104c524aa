"""The motion benchmark's report (Table I for both planners): its figures are the medians of the runs it is given, the
speedup is the ratio of the two medians, and the JSON names what the issue asks for. Synthetic runs: the planners' own
figures are measured by `regrasp bench motion`, never asserted on time."""
from __future__ import annotations

import json

from planner.cli.bench_motion import MotionBench
from planner.motion import PHASE_SECONDS, PHASES

SEARCH = [7.0, 6.5]  # the sequence search's stages, after the timing's seconds (wall time over the phases' work)


def _run(seed: int, seconds: float, checks: int, success: bool = True) -> dict:
    """One seed's record as bench_motion keeps it: every phase done, `checks` transit checks in each."""
    phases = [{"phase": name, "nodes_planning": 2, "nodes_validating": 0, "edges_invalidated": 1, "rrt_calls": 0,
               "searches": 1, "transit_checks": checks, "path_length": 1.0, "duration": 2.0} for name in PHASES]
    per_phase = [seconds / (len(PHASES) * len(PHASE_SECONDS) + 1)] * (len(PHASES) * len(PHASE_SECONDS)) + [0.0] + SEARCH
    return {"seed": seed, "seconds": seconds, "success": success, "double_grasp": 0, "phases": phases,
            "phase_seconds": per_phase, "phases_done": len(PHASES) if success else 0, "failure": "" if success else "x"}


def test_speedup_is_the_ratio_of_the_median_seconds_and_the_check_cost_is_reported():
    runs = {"roadmap": [_run(0, 1.0, 100), _run(1, 3.0, 300), _run(2, 2.0, 200, success=False)],
            "rrt": [_run(0, 8.0, 800), _run(1, 4.0, 400), _run(2, 6.0, 600)]}
    bench = MotionBench([0, 1, 2], runs, (61.5, 70.25))
    d = bench.to_dict()
    assert d["ours_total_seconds_median"] == 2.0 and d["rrt_total_seconds_median"] == 6.0
    assert d["speedup"] == 3.0
    assert d["ours_success"] == 2 / 3 and d["rrt_success"] == 1.0
    assert d["ours_transit_checks_median"] == 4 * 200 and d["check_ratio"] == 3.0
    assert (d["full_check_us_before"], d["full_check_us_after"]) == (61.5, 70.25)
    assert [p["phase"] for p in d["phases"]["ours"]] == list(PHASES)
    json.dumps(d)  # what --json writes
    text = bench.render()
    assert "speedup (RRTConnect median / ours): 3.00" in text
    assert "took 62 µs before the runs and 70 µs after" in text
    assert d["repeat"] == 1 and "fastest" not in text
    repeated = MotionBench([0, 1, 2], runs, (61.5, 70.25), repeat=3)
    assert repeated.to_dict()["repeat"] == 3 and "median 2.00 s over 3 seeds (the fastest of 3 runs each)" in repeated.render()


def _timed(seed: int, transit: float, other: float, pairs: int) -> dict:
    """A seed's record whose phases spend `transit` seconds in their transits (searching, validating, RRT, shortcutting)
    and `other` in contact motions and timing, with `pairs` narrow-phase pair tests in each phase's transits."""
    run = _run(seed, transit + other, 0)
    per = len(PHASE_SECONDS)
    seconds = [0.0] * (len(PHASES) * per) + [other / 2] + SEARCH
    for i in range(len(PHASES)):
        seconds[per * i: per * i + 4] = [transit / (4 * len(PHASES))] * 4
        seconds[per * i + 4] = other / (2 * len(PHASES))
    for phase in run["phases"]:
        phase["transit_pair_tests"] = pairs
    return {**run, "phase_seconds": seconds}


def test_transit_speedup_is_the_median_of_per_seed_ratios_and_pair_tests_are_medians():
    # per seed RRTConnect / ours: 2, 10, 3 -> median 3 (the ratio of the medians would be 5.0 / 1.0)
    runs = {"roadmap": [_timed(0, 1.0, 0.5, 10), _timed(1, 0.5, 0.5, 30), _timed(2, 2.0, 0.5, 20)],
            "rrt": [_timed(0, 2.0, 0.5, 50), _timed(1, 5.0, 0.5, 60), _timed(2, 6.0, 0.5, 100)]}
    d = MotionBench([0, 1, 2], runs).to_dict()
    assert abs(d["transit_speedup"] - 3.0) < 1e-9
    assert abs(d["ours_transit_seconds_median"] - 1.0) < 1e-9 and abs(d["rrt_transit_seconds_median"] - 5.0) < 1e-9
    assert d["ours_pair_tests_median"] == 4 * 20 and d["rrt_pair_tests_median"] == 4 * 60 and d["pair_test_ratio"] == 3.0
    assert [row["ours_pair_tests"] for row in d["per_seed"]] == [40, 120, 80]
    assert abs(d["per_seed"][1]["rrt_transit_seconds"] - 5.0) < 1e-9
    text = MotionBench([0, 1, 2], runs).render()
    assert "transit speedup (median over ours' runs of RRTConnect's transit seconds, same seed, / ours): 3.00" in text
    json.dumps(d)


def test_on_several_roadmaps_each_run_of_ours_is_paired_with_rrtconnect_on_its_seed():
    # ours on roadmaps 0 and 1 for seeds 0 and 1, RRTConnect once per seed (it uses no roadmap): the ratios are
    # 2/1, 5/1 on roadmap 0 and 2/4, 5/20 on roadmap 1, median 1.25 (pairing runs by position would give 3.5)
    runs = {"roadmap": [{**_timed(0, 1.0, 0.5, 10), "roadmap": 0}, {**_timed(1, 1.0, 0.5, 30), "roadmap": 0},
                        {**_timed(0, 4.0, 0.5, 50), "roadmap": 1}, {**_timed(1, 20.0, 0.5, 20), "roadmap": 1, "success": False}],
            "rrt": [{**_timed(0, 2.0, 0.5, 60), "roadmap": None}, {**_timed(1, 5.0, 0.5, 60), "roadmap": None}]}
    bench = MotionBench([0, 1], runs, roadmaps=2)
    d = bench.to_dict()
    assert abs(d["transit_speedup"] - 1.25) < 1e-9
    assert [(row["seed"], row["roadmap"], row["rrt_transit_seconds"]) for row in d["per_seed"]] == [
        (0, 0, 2.0), (1, 0, 5.0), (0, 1, 2.0), (1, 1, 5.0)]
    assert d["ours_pair_tests_median"] == 4 * 25  # over all four runs of ours
    assert [(r["roadmap"], r["pair_tests"], r["success"]) for r in d["per_roadmap"]] == [(0, 4 * 20, 1.0), (1, 4 * 35, 0.5)]
    assert d["per_roadmap"][1]["duration"] == 4 * 2.0  # the successful run's
    # summed with RRTConnect's run of each seed once per run of ours: pair tests 4 * (10 + 30 + 50 + 20) against
    # 4 * 60 * 4; seconds 1.5 + 1.5 + 4.5 + 20.5 against 2.5 + 5.5 + 2.5 + 5.5
    assert (d["ours_pair_tests_total"], d["rrt_pair_tests_total"]) == (440, 960)
    assert abs(d["pair_test_ratio_total"] - 960 / 440) < 1e-9
    assert (d["ours_seconds_total"], d["rrt_seconds_total"]) == (28.0, 16.0) and abs(d["speedup_total"] - 16 / 28) < 1e-9
    text = bench.render()
    assert "over 2 seeds x 2 roadmaps" in text and "ours per roadmap" in text
    assert "ours / RRTConnect: transit pair tests 440 / 960 (RRTConnect / ours 2.18), step 28.0 / 16.0 s (0.57)" in text
    json.dumps(d)


def test_where_the_time_goes_reads_the_timing_after_the_phases_not_the_search_stages_after_it():
    runs = {"roadmap": [_timed(0, 1.0, 0.4, 10), _timed(1, 1.0, 0.6, 10), _timed(2, 1.0, 0.8, 10)],
            "rrt": [_timed(0, 2.0, 0.5, 50)] * 3}
    where = MotionBench([0, 1, 2], runs).where("roadmap")
    assert abs(where["timing and sampling"] - 0.3) < 1e-9  # the median of 0.2, 0.3, 0.4: never the search's 6.5
    assert abs(where["contact motions"] - 0.3) < 1e-9 and abs(where["graph search"] - 0.25) < 1e-9
    assert abs(where["other"]) < 1e-9  # each run's seconds are its phases' and its timing's


def test_the_transits_of_the_sequences_given_up_count_in_the_runs_figures():
    # ours gave up sequences on seeds 1 and 2 (500 and 40 pair tests, 0.5 and 2.0 s, 7 and 9 checks); its per-seed
    # pair tests 40 + 500, 120, 80 + 40 -> 540, 120, 120: median 120; transit seconds 1.5, 0.5, 4.0 -> ratios 4/3, 10, 1.5
    runs = {"roadmap": [{**_timed(0, 1.0, 0.5, 10), "given_up": {"checks": 7, "pair_tests": 500, "seconds": 0.5}},
                        _timed(1, 0.5, 0.5, 30),
                        {**_timed(2, 2.0, 0.5, 20), "given_up": {"checks": 9, "pair_tests": 40, "seconds": 2.0}}],
            "rrt": [_timed(0, 2.0, 0.5, 50), _timed(1, 5.0, 0.5, 60), _timed(2, 6.0, 0.5, 100)]}
    d = MotionBench([0, 1, 2], runs).to_dict()
    assert [row["ours_pair_tests"] for row in d["per_seed"]] == [540, 120, 120] and d["ours_pair_tests_median"] == 120
    assert [round(row["ours_transit_seconds"], 9) for row in d["per_seed"]] == [1.5, 0.5, 4.0]
    assert abs(d["transit_speedup"] - 1.5) < 1e-9
    assert d["ours_transit_checks_median"] == 7  # of 7, 0, 9: the phases' own checks are 0 in these records


def test_the_transits_pair_tests_are_split_by_part_and_bound_what_the_ratios_could_reach():
    # per phase: ours 30 pair tests, of which RRTConnect 12 and shortcuts 6 (seed 0), 9, 3 and the arm moved away 3
    # (seed 1); RRTConnect alone 100, all but its ends' 10 in its queries and shortcuts (a record from before the arm moved
    # away was counted apart: none). What no roadmap answers, ours' shortcutting and arm moved away: 4 * 6 and 4 * (3 + 3)
    # -> median 24; RRTConnect's pair tests 400 -> the ratio at most 400 / 24 were ours' ends, graph and reconnections free
    def parted(seed: int, transit: float, pairs: int, rrt: int, cut: int, away: int | None = None) -> dict:
        run = _timed(seed, transit, 0.5, pairs)
        for phase in run["phases"]:
            phase.update(transit_pair_tests_rrt=rrt, transit_pair_tests_shortcut=cut)
            if away is not None:
                phase["transit_pair_tests_away"] = away
        return run

    gave_up = {"checks": 1, "pair_tests": 8, "seconds": 0.0}
    runs = {"roadmap": [parted(0, 1.0, 30, 12, 6), {**parted(1, 3.0, 30, 9, 3, 3), "given_up": gave_up}],
            "rrt": [parted(0, 2.0, 100, 60, 30), parted(1, 2.0, 100, 60, 30)]}
    d = MotionBench([0, 1], runs).to_dict()
    assert d["ours_pair_tests_by_part"] == {"ends and graph": 4 * 27 / 2, "RRTConnect": 4 * 21 / 2, "shortcutting": 4 * 9 / 2,
                                            "arm away": 4 * 3 / 2, "given up": 4}
    assert d["rrt_pair_tests_by_part"] == {"ends and graph": 40, "RRTConnect": 240, "shortcutting": 120, "arm away": 0,
                                           "given up": 0}
    assert abs(d["pair_test_ratio_bound"] - 400 / 24) < 1e-9
    # the step less its transits: 0.5 s for every run -> RRTConnect's median 2.5 s over 0.5 s
    assert abs(d["speedup_bound"] - 5.0) < 1e-9
    text = MotionBench([0, 1], runs).render()
    assert ("where the transits' pair tests go (median): ends and graph 54, RRTConnect 42, shortcutting 18, arm away 6, "
            "given up 4") in text
    assert "at most 16.67 were ours' ends, graph and RRT reconnections free" in text
    assert "at most 5.00 were ours' transits free" in text
    json.dumps(d)


def _smoothing_run(seed: int, seconds: float, bare: float, duration: float, bare_duration: float, checks: int,
                   success: bool = True) -> dict:
    """One seed's record as bench_smoothing keeps it: the step's seconds and the motion's duration with the smoothing
    and without it; per pass, attempts 100, 10 and 1,000 per second of the checks, half the saving by the first pass."""
    saved = bare_duration - duration
    return {"seed": seed, "success": success, "failure": "" if success else "Place phase: no path", "seconds": seconds,
            "unsmoothed_seconds": bare, "timing_seconds": seconds - bare + 0.1, "unsmoothed_timing_seconds": 0.1,
            "duration": duration, "unsmoothed_duration": bare_duration, "smoothing_checks": checks,
            "smoothing_attempts": [checks // 100, checks // 1000, checks // 10], "smoothing_kept": [3, 2, 1],
            "smoothing_saved": [saved / 2, saved / 4, saved / 4]}


def test_the_smoothings_planning_growth_is_the_median_of_per_seed_ratios_over_the_runs_that_moved():
    from planner.cli.bench_smoothing import SmoothingBench

    # per seed smoothed / unsmoothed - 1: 0.5, 0.1, 0.3 -> 0.3 (the ratio of the medians would be 1.5 / 1.0 - 1 = 0.5)
    runs = [_smoothing_run(0, 1.5, 1.0, 20.0, 40.0, 6000), _smoothing_run(1, 2.2, 2.0, 22.0, 42.0, 8000),
            _smoothing_run(2, 1.3, 1.0, 21.0, 45.0, 7000), _smoothing_run(3, 9.0, 1.0, 0.0, 0.0, 0, success=False)]
    bench = SmoothingBench([0, 1, 2, 3], runs)
    d = bench.to_dict()
    assert abs(d["planning_growth_median"] - 0.3) < 1e-12 and d["growth_target"] == 0.2
    assert d["success"] == 0.75 and d["step_seconds_median"] == 1.5 and d["unsmoothed_step_seconds_median"] == 1.0
    assert d["duration_median"] == 21.0 and d["unsmoothed_duration_median"] == 42.0 and d["saved_median"] == 20.0
    assert d["checks_per_second_saved"] == 21000 / (20.0 + 20.0 + 24.0) and d["smoothing_checks_median"] == 7000
    json.dumps(d)  # what --json writes
    text = bench.render()
    assert "the smoothing adds 30% to the step's planning time" in text and "at most 20% asked" in text
    assert "1.00 -> 1.50 s (medians)" in text and "42.00 -> 21.00 s" in text
    assert "3       no motion: Place phase: no path" in text
    passes = d["passes"]  # summed over the three seeds that moved (21,000 checks, 64 s saved)
    assert list(passes) == ["vertices", "corners", "random"]
    assert passes["vertices"] == {"attempts": 210, "kept": 9, "saved": 32.0} and passes["random"]["attempts"] == 2100
    assert passes["corners"]["saved"] == 16.0 and "random         2100     3    16.00                   131" in text


def test_phases_split_by_whether_the_graph_joined_their_ends_sum_pair_tests_less_the_arm_moved_away():
    # seed 0: ours' Carry has an end no graph edge joins; seed 1: ours planned another double grasp than RRTConnect's,
    # so its phases are compared with none
    ours, rrt = _timed(0, 1.0, 0.5, 10), _timed(0, 2.0, 0.5, 40)
    ours["phases"][1].update(ends_alone=1, transit_pair_tests=70)
    ours["phases"][2].update(transit_pair_tests=15, transit_pair_tests_away=5)
    rrt["phases"][2].update(transit_pair_tests=45, transit_pair_tests_away=5)
    other = {**_timed(1, 1.0, 0.5, 10), "double_grasp": 3}
    bench = MotionBench([0, 1], {"roadmap": [ours, other], "rrt": [rrt, _timed(1, 2.0, 0.5, 40)]})
    d = bench.to_dict()
    assert (d["phases_joined"], d["ours_pair_tests_joined"], d["rrt_pair_tests_joined"]) == (3, 10 + 10 + 10, 40 + 40 + 40)
    assert (d["phases_alone"], d["ours_pair_tests_alone"], d["rrt_pair_tests_alone"]) == (1, 70, 40)
    assert d["pair_test_ratio_joined"] == 4.0 and abs(d["pair_test_ratio_alone"] - 40 / 70) < 1e-12
    assert "phases with a query end no graph edge joins: 1, their transit pair tests less the arm moved away, ours / " \
           "RRTConnect 70 / 40 (RRTConnect / ours 0.57" in bench.render()


def test_a_kind_of_phase_none_of_the_runs_has_gets_no_ratio_and_the_json_stays_strict():
    bench = MotionBench([0], {"roadmap": [_timed(0, 1.0, 0.5, 10)], "rrt": [_timed(0, 2.0, 0.5, 40)]})
    d = bench.to_dict()
    assert d["phases_alone"] == 0 and d["pair_test_ratio_alone"] is None and d["pair_test_ratio_joined"] == 4.0
    json.dumps(d["per_seed"], allow_nan=False)
    json.dumps({k: v for k, v in d.items() if k.endswith(("_joined", "_alone"))}, allow_nan=False)
    assert "phases with a query end no graph edge joins: 0\n" in bench.render()
