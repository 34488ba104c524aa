"""The Task tab's task controls: the task chosen from the project's tasks or typed as a file, its name and description,
and why a task was refused (the workbench loads it; this only shows and reads the controls)."""
from __future__ import annotations

from pathlib import Path

import viser

from planner.core.errors import RegraspError
from planner.core.paths import PROJECT_ROOT, TASKS_DIR
from planner.core.plain_text import plain
from planner.core.session import MANIFEST, Session
from planner.model.task import Scene


def task_choices(current: Path) -> dict[str, Path]:
    """Dropdown label -> file for the tasks in assets/tasks, plus the current task if it lives elsewhere."""
    choices = {p.stem: p.resolve() for p in sorted(TASKS_DIR.glob("*.toml"))}
    if current.resolve() not in choices.values():
        label = f"session {current.parent.name}" if current.name == MANIFEST else str(current)  # a replayed session's task
        choices[label] = current.resolve()
    return choices


class TaskTab:
    """The task dropdown, the "Task file" field with "Load file", the task's description and the refusal line."""

    def __init__(self, gui: viser.GuiApi, scene: Scene):
        self.roots = (PROJECT_ROOT, scene.source.resolve().parent)  # where "Load file" may read task files
        self.files = task_choices(scene.source)
        self.syncing = False  # True while `show` rewrites the dropdown: its callback must not load a task
        self.choice = gui.add_dropdown("Task", tuple(self.files), initial_value=self.label_of(scene.source))
        self.path = gui.add_text("Task file", str(scene.source))
        self.load_button = gui.add_button("Load file")
        self.info = gui.add_markdown("")
        self.error = gui.add_markdown("", visible=False)

    def label_of(self, path: Path) -> str:
        """The task dropdown's label for a task file."""
        return next(label for label, p in self.files.items() if p == path.resolve())

    def chosen(self) -> Path:
        """The file of the task the dropdown names."""
        return self.files[self.choice.value]

    def typed(self, text: str) -> Path:
        """The task file typed in "Task file": a .toml file in the project or in the folder of the task the workbench
        started with (a browser must not make the workbench read any file it likes)."""
        path = Path(text.strip()).expanduser().resolve()
        if path.suffix != ".toml" or not any(path.is_relative_to(root) for root in self.roots):
            where = " or ".join(str(root) for root in dict.fromkeys(self.roots))
            raise RegraspError(f"Task file: expected a .toml file in {where}, got {text.strip()!r:.200}")
        return path

    def refuse(self, title: str, message: str, client: viser.ClientHandle | None) -> None:
        """Say under the task (and to the asking tab) why the task shown stays."""
        self.error.content = f"**{title}:** {plain(message)}"
        self.error.visible = True
        if client is not None:
            client.add_notification(title, message, color="red", auto_close_seconds=10.0)

    def choose(self, scene: Scene) -> None:
        """Make the dropdown name `scene` (e.g. back to the task shown when another was refused), loading nothing."""
        self.files = task_choices(scene.source)
        self.syncing = True  # viser calls on_update synchronously, within this block
        try:
            self.choice.options = tuple(self.files)
            self.choice.value = self.label_of(scene.source)
        finally:
            self.syncing = False

    def show(self, scene: Scene, session: Session | None) -> None:
        """Make the controls name `scene` (a replayed session's task as the session names it), without loading anything."""
        self.choose(scene)
        # a replayed session's task file is its session.json: show the task it came from (a name or a relative path)
        self.path.value = session.manifest.get("task_source", "") if session is not None and scene is session.scene \
            else str(scene.source)
        about = f" — {plain(scene.description)}" if scene.description else ""
        self.info.content = f"**{plain(scene.name)}**{about}"
