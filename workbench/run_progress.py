"""A run's progress in the panel: one bar over the steps a run does, and a line naming the step and what it reports."""
from __future__ import annotations

import viser

from planner.core.plain_text import plain
from planner.core.runner import ProgressFactory
from planner.core.steps import Progress, Step


def progress_factory(bar: viser.GuiProgressBarHandle, text: viser.GuiMarkdownHandle, todo: list[Step]) -> ProgressFactory:
    """Per step of `todo`, a callback moving `bar` over this run's share of that step and saying its message in `text`."""
    names = [s.name for s in todo]

    def factory(step: Step) -> Progress:
        i = names.index(step.name)

        def report(fraction: float, message: str = "") -> None:
            bar.value = round(100 * (i + min(max(fraction, 0.0), 1.0)) / len(names), 1)
            text.content = f"*{step.name}* ({i + 1}/{len(names)}): {plain(message)}"
        return report
    return factory
