"""regrasp planner: the headless backend of the two-hand regrasping workbench."""

__version__ = "0.1.0"
