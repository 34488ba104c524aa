"""Step layers: one per step that has something to draw. A new layer = one module here + one line in LAYERS."""
from __future__ import annotations

from .arms import ArmsLayer
from .base import StepLayer

LAYERS: dict[str, type[StepLayer]] = {
    "arms": ArmsLayer,
}
