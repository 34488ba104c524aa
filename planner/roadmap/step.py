"""The roadmap step: build the offline roadmap or load it from the user cache (keyed by all it depends on)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from planner.collision.pairs import CODE_VERSION as PAIRS_VERSION
from planner.core.results import load_result, read_only, save_result
from planner.core.steps import Progress, Step, StepContext, StepOutput, no_progress, step_seed
from planner.core.user_cache import building, cache_path, computing, read_cached
from planner.core.user_cache import cache_key as hash_key
from planner.model.task import Scene
from planner.roadmap.build import build_roadmap
from planner.roadmap.result import Roadmap, RoadmapParams

CODE_VERSION = "roadmap-4"  # 2: no timings in the roadmap; 3: nodes around the task's sites; 4: each pair checked as densely as it needs


def cache_key(scene: Scene, params: RoadmapParams, seed: int) -> str:
    """A hash of the robot spec and its URDFs, the obstacles, the parameters, the seed and the code version; with task
    nodes, also the task's sites' inputs (its start and end configurations, the object and its placements)."""
    robot = scene.robot
    parts: list[str | bytes] = [CODE_VERSION, PAIRS_VERSION, robot.spec.text(), repr((params, seed))]
    if params.task_nodes:
        parts += [a.tobytes() for a in (scene.q_initial, scene.q_final, scene.object_initial, scene.object_final,
                                         scene.object_mesh.vertices, scene.object_mesh.faces)]
    parts += [Path(p).read_bytes() for p in [robot.spec.body_urdf] + [a.hand.urdf for a in robot.spec.arms]]
    for ob in scene.environment:
        parts += [repr((ob.name, ob.shape, ob.size)), ob.pose.tobytes()]
        if ob.mesh is not None:
            parts += [ob.mesh.vertices.tobytes(), ob.mesh.faces.tobytes()]
    return hash_key(*parts)


def roadmap_for(scene: Scene, params: RoadmapParams, seed: int, use_cache: bool = True,
                progress: Progress = no_progress) -> tuple[Roadmap, dict[str, float]]:
    """(the roadmap, the seconds of each stage built: empty when it came from the cache); a built roadmap is written to the cache."""
    path = cache_path("roadmaps", cache_key(scene, params, seed))
    with computing(path):
        if use_cache:
            cached = read_cached([path.with_suffix(".json"), path.with_suffix(".npz")],
                                 lambda: load_result(Roadmap, path.parent, path.name), "roadmap")
            if cached is not None:
                return cached, {}
        with building(f"the roadmap ({params.nodes} nodes per elementary roadmap, entry {path.name})"):
            roadmap, seconds = build_roadmap(scene, params, seed, progress)
            save_result(roadmap, path.parent, path.name)
    return read_only(roadmap), seconds


def seed_of(rng: np.random.Generator) -> int:
    """The roadmap's seed, drawn from the step's generator (so the session seed decides it)."""
    return int(rng.integers(2**63))


def session_roadmap_seed(session_seed: int) -> int:
    """The seed a session with this seed builds its roadmap with (for the command line)."""
    return seed_of(np.random.default_rng(step_seed(session_seed, NAME)))


def run(ctx: StepContext) -> StepOutput:
    roadmap, seconds = roadmap_for(ctx.scene, ctx.params, seed_of(ctx.rng), progress=ctx.progress)
    return StepOutput(roadmap, tuple(seconds.values()), cached=not seconds)


NAME = "roadmap"
STEP = Step(NAME, "offline per-arm Vis-PRM roadmaps merged into the Super Graph (V-A)", (), RoadmapParams, Roadmap, run)
