"""The regrasp web workbench (viser): draws what `planner` computes; holds no planning logic."""
from .app import Workbench, run

__all__ = ["Workbench", "run"]
