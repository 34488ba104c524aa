"""Step layers: one per step that has something to draw. A new layer = one module here + one line in LAYERS."""
from __future__ import annotations

from .arms import ArmsLayer
from .base import StepLayer
from .double_grasps import DoubleGraspsLayer
from .exchange import ExchangeLayer
from .grasp_configs import GraspConfigsLayer
from .grasps import PickGraspsLayer, PlaceGraspsLayer
from .motion import MotionLayer
from .placements import PlacementsLayer
from .roadmap import RoadmapLayer

LAYERS: dict[str, type[StepLayer]] = {
    "arms": ArmsLayer,
    "pick_grasps": PickGraspsLayer, "place_grasps": PlaceGraspsLayer,
    "grasp_configs": GraspConfigsLayer,
    "exchange": ExchangeLayer,
    "double_grasps": DoubleGraspsLayer,
    "roadmap": RoadmapLayer,
    "placements": PlacementsLayer,
    "motion": MotionLayer,
}
