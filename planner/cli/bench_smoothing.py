"""`regrasp bench smoothing`: the motion step planned with its smoothing and without it, from the same inputs and in
the same minutes, per seed: how much planning time the smoothing adds against how much motion time it saves."""
from __future__ import annotations

from dataclasses import dataclass, replace

from planner.cli.bench_motion import bench_inputs, median, seed_inputs, timed_motion
from planner.model.task import Scene
from planner.motion.smoothing import PASSES

GROWTH_TARGET = 0.20  # the planning time the smoothing may add, as a share of the step planned without it (issue 34)


@dataclass(frozen=True)
class SmoothingBench:
    """Per seed, the motion step with the smoothing (`--set` as given) and without it (no shortcut attempted)."""

    seeds: list
    runs: list  # per seed: {"seed", "success", "seconds", "unsmoothed_seconds", "timing_seconds", "unsmoothed_timing_seconds",
    #              "duration", "unsmoothed_duration", "smoothing_checks", and per pass (PASSES) "smoothing_attempts",
    #              "smoothing_kept", "smoothing_saved"}
    repeat: int = 1  # runs per seed and setting, the fastest kept

    def moved(self) -> list:
        """The seeds' records whose motion was planned with and without the smoothing."""
        return [r for r in self.runs if r["success"]]

    def to_dict(self) -> dict:
        ok = self.moved()
        growth = [r["seconds"] / r["unsmoothed_seconds"] - 1.0 for r in ok if r["unsmoothed_seconds"] > 0]
        saved = [r["unsmoothed_duration"] - r["duration"] for r in ok]
        checks = sum(r["smoothing_checks"] for r in ok)
        return {"seeds": self.seeds, "repeat": self.repeat, "success": len(ok) / len(self.runs) if self.runs else float("nan"),
                "step_seconds_median": median([r["seconds"] for r in ok]),
                "unsmoothed_step_seconds_median": median([r["unsmoothed_seconds"] for r in ok]),
                "planning_growth_median": median(growth), "growth_target": GROWTH_TARGET,
                "timing_seconds_median": median([r["timing_seconds"] for r in ok]),
                "unsmoothed_timing_seconds_median": median([r["unsmoothed_timing_seconds"] for r in ok]),
                "duration_median": median([r["duration"] for r in ok]),
                "unsmoothed_duration_median": median([r["unsmoothed_duration"] for r in ok]),
                "saved_median": median(saved), "smoothing_checks_median": median([r["smoothing_checks"] for r in ok]),
                "checks_per_second_saved": checks / sum(saved) if sum(saved) > 0 else float("nan"),
                "passes": self.passes(), "runs": self.runs}

    def passes(self) -> dict:
        """Per pass of the smoothing, summed over the seeds that moved: shortcuts attempted anew, kept, seconds saved."""
        ok = self.moved()
        return {name: {"attempts": sum(r["smoothing_attempts"][k] for r in ok), "kept": sum(r["smoothing_kept"][k] for r in ok),
                       "saved": sum(r["smoothing_saved"][k] for r in ok)} for k, name in enumerate(PASSES)}

    def render(self) -> str:
        d = self.to_dict()
        fastest = f", the fastest of {self.repeat} runs each" if self.repeat > 1 else ""
        out = [f"the motion step with and without smoothing, {len(self.seeds)} seeds{fastest}",
               f"{'seed':<6}{'step s':>8}{'unsmoothed':>11}{'growth':>8}{'timing s':>10}{'unsmoothed':>11}{'motion s':>10}"
               f"{'unsmoothed':>11}{'checks':>8}"]
        for r in self.runs:
            if not r["success"]:
                out.append(f"{r['seed']:<6}  no motion: {r['failure'][:100]}")
                continue
            out.append(f"{r['seed']:<6}{r['seconds']:>8.2f}{r['unsmoothed_seconds']:>11.2f}"
                       f"{r['seconds'] / r['unsmoothed_seconds'] - 1.0:>8.0%}{r['timing_seconds']:>10.2f}"
                       f"{r['unsmoothed_timing_seconds']:>11.2f}{r['duration']:>10.2f}{r['unsmoothed_duration']:>11.2f}"
                       f"{r['smoothing_checks']:>8}")
        out += ["", f"the smoothing adds {d['planning_growth_median']:.0%} to the step's planning time (median over the seeds of "
                f"each seed's ratio; at most {GROWTH_TARGET:.0%} asked): {d['unsmoothed_step_seconds_median']:.2f} -> "
                f"{d['step_seconds_median']:.2f} s (medians), its timing and sampling {d['unsmoothed_timing_seconds_median']:.2f} "
                f"-> {d['timing_seconds_median']:.2f} s (the transit workers' smoothing seconds included: they overlap the "
                "transits)",
                f"and shortens the motion by {d['saved_median']:.2f} s (median): {d['unsmoothed_duration_median']:.2f} -> "
                f"{d['duration_median']:.2f} s, with {d['smoothing_checks_median']:.0f} collision checks (median; "
                f"{d['checks_per_second_saved']:.0f} per second saved over the seeds: counts, the same on any machine)",
                "", "per pass, summed over the seeds (counts):", f"{'pass':<10}{'attempts':>9}{'kept':>6}{'saved s':>9}"
                f"{'attempts per s saved':>22}"]
        for name, row in d["passes"].items():
            per = f"{row['attempts'] / row['saved']:.0f}" if row["saved"] > 0 else "-"
            out.append(f"{name:<10}{row['attempts']:>9}{row['kept']:>6}{row['saved']:>9.2f}{per:>22}")
        return "\n".join(out)


def bench_smoothing(scene: Scene, seeds: int, folder, progress=print, repeat: int = 1,
                    params: dict | None = None) -> SmoothingBench:
    """The offline steps once (seed 0, from the cache when there); per seed the online steps, then the motion planned
    with the smoothing (the motion parameters as `params` set them) and without it (smooth_checks_per_s and
    smooth_attempts_per_s 0: the pieces timed rest to rest at every vertex), alternately, `repeat` times each, the fastest kept."""
    params = params or {}
    made, offline, (graph,) = bench_inputs(scene, folder, progress, params)
    unsmoothed = replace(made["motion"], smooth_checks_per_s=0.0, smooth_attempts_per_s=0.0)
    runs = []
    for seed in range(seeds):
        results = seed_inputs(scene, made, offline, graph, seed)
        timed = [(timed_motion(scene, results, made, made["motion"], seed), timed_motion(scene, results, made, unsmoothed, seed))
                 for _ in range(repeat)]
        (elapsed, motion, seconds), (bare_elapsed, bare, bare_seconds) = (min((t[k] for t in timed), key=lambda t: t[0])
                                                                          for k in (0, 1))
        row = {"seed": seed, "success": not motion.failure and not bare.failure, "failure": motion.failure or bare.failure,
               "seconds": elapsed, "unsmoothed_seconds": bare_elapsed,
               "timing_seconds": _timing(motion, seconds), "unsmoothed_timing_seconds": _timing(bare, bare_seconds),
               "duration": float(motion.duration), "unsmoothed_duration": float(bare.duration),
               "smoothing_checks": int(sum(p.get("smoothing_checks", 0) for p in motion.phases)),
               **{key: [sum(p.get(key, [0] * len(PASSES))[k] for p in motion.phases) for k in range(len(PASSES))]
                  for key in ("smoothing_attempts", "smoothing_kept", "smoothing_saved")}}
        runs.append(row)
        progress(f"seed {seed}: {elapsed:.2f} s smoothed ({row['duration']:.2f} s of motion), {bare_elapsed:.2f} s without "
                 f"({row['unsmoothed_duration']:.2f} s)" if row["success"] else f"seed {seed}: {row['failure'][:120]}")
    return SmoothingBench(list(range(seeds)), runs, repeat)


def _timing(motion, seconds: list) -> float:
    """The seconds of the motion step's timing and sampling (after its phases' transit and contact figures): the
    smoothing's in the transit workers, which overlap the transits, and the rest's after them."""
    from planner.motion import PHASE_SECONDS

    return float(seconds[len(PHASE_SECONDS) * len(motion.phases)])
