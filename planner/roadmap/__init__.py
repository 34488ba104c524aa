"""The offline multi-arm roadmap (paper V-A): per-arm Vis-PRM roadmaps composed into the Super Graph."""
from planner.roadmap.result import Roadmap, RoadmapParams
from planner.roadmap.step import STEP, roadmap_for

__all__ = ["Roadmap", "RoadmapParams", "STEP", "roadmap_for"]
