"""The panel's tabs (viser tab group): Task, Steps, Playback, Joints, View, so that no control sits below a long scroll.

Each tab is a viser container: `with tabs.steps: gui.add_...` places a control in it. The Task tab is also
where task editing adds its controls (see `PanelTabs.task`).
"""
from __future__ import annotations

import viser

TAB_NAMES = ("Task", "Steps", "Playback", "Joints", "View")
PLAYBACK_EMPTY = "*Run the motion step (Steps tab), or load a session that has one, to play it here.*"


class PanelTabs:
    """The workbench panel's tab group and its five tabs, made in `TAB_NAMES` order (no icons: the five names fit on one
    row of the panel)."""

    def __init__(self, gui: viser.GuiApi):
        self.group = gui.add_tab_group()
        self.task = self.group.add_tab("Task")
        """The Task tab: the task's choice and file, its description, then the session's name, save and load.

        The hook for task editing: a module adding editing controls places them with `with workbench.tabs.task:` (they
        come after what is there when added). Kept stable: other modules depend on this attribute's name and kind."""
        self.steps = self.group.add_tab("Steps")
        """The step table, the step in focus and its controls, and the runs."""
        self.playback = self.group.add_tab("Playback")
        """The motion's timeline, play / pause, loop, speed, trails and downloads (the motion layer fills it)."""
        self.joints = self.group.add_tab("Joints")
        """One slider per joint of a chosen part, and reset."""
        self.view = self.group.add_tab("View")
        """Camera moves, what is shown, and one checkbox per step layer."""
        with self.playback:
            self.playback_empty = gui.add_markdown(PLAYBACK_EMPTY)
