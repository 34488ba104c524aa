"""`python -m planner.cli`: the headless commands alone (no workbench needed, e.g. on a cluster node)."""
import sys

from planner.cli.main import main

sys.exit(main())
