"""Step layers: one per step that has something to draw. A new layer = one module here + one line in LAYERS."""
from __future__ import annotations

from .arms import ArmsLayer
from .grasps import PickGraspsLayer, PlaceGraspsLayer
from .base import StepLayer
from .roadmap import RoadmapLayer

LAYERS: dict[str, type[StepLayer]] = {
    "arms": ArmsLayer,
    "pick_grasps": PickGraspsLayer, "place_grasps": PlaceGraspsLayer,
    "roadmap": RoadmapLayer,
}
