"""The session panel's questions, each a modal dialog in the asking browser tab: overwrite a saved session, and what to
do with unsaved steps before another task or session replaces them (work is never lost silently)."""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import viser

from planner.core.plain_text import plain

SAVE, KEEP, DISCARD, CANCEL = "save", "keep", "discard", "cancel"  # the answers to `ask_unsaved`


def confirm_overwrite(client: viser.ClientHandle, folder: Path, confirmed: Callable[[], None]) -> None:
    """Ask whether the session saved in `folder` may be replaced; `confirmed` runs on "Overwrite"."""
    with client.gui.add_modal(f"Overwrite sessions/{folder.name}?") as modal:
        client.gui.add_markdown(f"*{plain(folder)}* already exists. Replace it with the current session?")
        overwrite = client.gui.add_button("Overwrite", color="red")
        cancel = client.gui.add_button("Cancel")

    def clicked(_: Any) -> None:
        modal.close()
        confirmed()

    overwrite.on_click(clicked)
    cancel.on_click(lambda _: modal.close())


def ask_unsaved(client: viser.ClientHandle, steps: list[str], what: str, name: str, kept_as: str,
                answer: Callable[[str], None]) -> None:
    """Ask, before `what` (e.g. "load the task baxter") replaces them, what to do with the unsaved `steps`: save them as
    sessions/<name>, keep them as sessions/<kept_as> (what closing does too), discard them, or cancel; `answer` gets one
    of SAVE, KEEP, DISCARD, CANCEL once a button is clicked."""
    listed = ", ".join(plain(s) for s in steps)
    with client.gui.add_modal("Unsaved steps") as modal:
        client.gui.add_markdown(
            f"The steps run here are not saved: **{listed}**. Before you {plain(what)}:\n\n"
            f"- **Save** them as *sessions/{plain(name)}* (the Name field),\n"
            f"- **Keep** them as *sessions/{plain(kept_as)}*, listed under Saved (closing the workbench keeps them so too),\n"
            f"- **Discard** them, or **Cancel** and stay here.")
        buttons = {SAVE: client.gui.add_button(f"Save as {name}", color="green"),
                   KEEP: client.gui.add_button(f"Keep as {kept_as}"),
                   DISCARD: client.gui.add_button("Discard", color="red"),
                   CANCEL: client.gui.add_button("Cancel")}

    def clicked(choice: str) -> None:
        modal.close()
        answer(choice)

    for choice, button in buttons.items():
        button.on_click(lambda _, choice=choice: clicked(choice))
