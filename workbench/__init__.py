"""The regrasp web workbench (viser): draws what `planner` computes; holds no planning logic. Its modules are imported
where they are used: the command line (workbench.cli) loads viser only for the commands that open the workbench."""
