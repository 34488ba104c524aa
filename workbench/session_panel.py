"""The Session panel: save and load sessions, the step table, runs in the background, re-run from here, export.

It holds no planning logic: runs go through `planner.core.runner`, and the workbench draws the session
that comes back. The workbench never writes into a folder it loaded: runs go into a scratch
session (a loaded one is first branched into it), Save copies into `sessions/<name>` and re-run
branches into a new `sessions/<name>-rerun-N`.
"""
from __future__ import annotations

import re
import threading
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import viser

from planner.core.bounds import SEED, seed_problem
from planner.core.errors import RegraspError
from planner.core.forked import stop_pools
from planner.core.plain_text import plain
from planner.core.runner import run_pipeline
from planner.core.session import Session
from planner.pipeline import PIPELINE, step_named, steps_until

from .export import scene_html
from .layers.base import Pose
from .notify import error_text, notify_all
from .param_inputs import ParamInputs, recorded_params, whole
from .pose_choice import INITIAL, OTHER
from .run_progress import progress_factory
from .session_dialogs import CANCEL, DISCARD, SAVE, ask_unsaved, confirm_overwrite
from .session_layers import SessionLayers
from .session_store import (
    check_name,
    discard_scratch,
    free_name,
    list_sessions,
    save_copy,
    scratch_copy,
    scratch_folder,
    unsaved_name,
    unsaved_steps,
)
from .step_table import step_details, step_table

if TYPE_CHECKING:
    from .app import Workbench

NO_SESSIONS = "(no saved sessions)"
NO_STEP = "(no step has run)"
JOIN_SECONDS = 10.0  # how long closing waits for a stopped run to end before deleting its scratch session


class SessionPanel:
    """The 'Session' GUI folder and its actions (also callable from code: tests drive them directly)."""

    def __init__(self, workbench: Workbench, sessions_dir: Path):
        self.wb = workbench
        self.sessions_dir = sessions_dir
        self.job: threading.Thread | None = None
        self._starting = threading.Lock()  # makes "is a run going? then start one" one step
        self._scratch: Path | None = None  # the session folder the GUI created; the only one runs write into
        self._saved_records: list | None = None  # the scratch session's step records when it was last saved
        self._params: ParamInputs | None = None
        gui = workbench.server.gui
        names = tuple(s.name for s in PIPELINE)
        with workbench.tabs.task, gui.add_folder("Session"):
            self.name = gui.add_text("Name", "untitled")
            self.save_button = gui.add_button("Save", hint="Save the current session as sessions/<name>")
            self.saved = gui.add_dropdown("Saved", self._saved_options())
            self.load_button = gui.add_button("Load", hint="Replay a saved session: nothing is recomputed")
            self.export_button = gui.add_button("Export HTML", hint="Download what is shown as one HTML file that plays offline")
        with workbench.tabs.steps:
            self.message = gui.add_markdown("", visible=False)
            self.table = gui.add_markdown(step_table(None))
            self.next_button = gui.add_button("Run the next step")
            self.until = gui.add_dropdown("Up to", names, initial_value=names[-1])
            self.until_button = gui.add_button("Run up to this step")
            self.seed = gui.add_number("Seed", 0, min=SEED.low, step=1, hint=f"The seed of a session started here ({SEED.describe()})")
            self.progress = gui.add_progress_bar(0.0, visible=False)
            self.progress_text = gui.add_markdown("", visible=False)
            self.step = gui.add_dropdown("Step", (NO_STEP,), hint="The step in focus: its layer alone in view, its controls "
                                         "and details below")
            self.step_controls = gui.add_folder(None)  # the layer of the step in focus puts its folder here
            with gui.add_folder("Step details", expand_by_default=False):
                self.details = gui.add_markdown("")
            with gui.add_folder("Re-run from here", expand_by_default=False):
                self.rerun_step = gui.add_dropdown("Step", names)
                self._params_folder = gui.add_folder("Parameters")
                self.rerun_button = gui.add_button("Re-run into a new session")
        # disabled while a run goes, the task's "Load file" and choice included (a task loaded meanwhile would be thrown away)
        self._buttons = (self.save_button, self.load_button, self.next_button, self.until_button, self.rerun_button,
                         workbench.task_tab.load_button, workbench.task_tab.choice)
        self.step.on_update(lambda e: self._step_chosen(e.target.value))
        self.save_button.on_click(lambda e: self._save_clicked(e.client))
        self.load_button.on_click(lambda e: self._load_clicked(e.client))
        self.next_button.on_click(lambda _: self.run_next())
        self.until_button.on_click(lambda _: self.run_until(self.until.value))
        self.rerun_step.on_update(lambda _: self._rebuild_params())
        self.rerun_button.on_click(lambda _: self.rerun(self.rerun_step.value, self._params.values() if self._params else {}))
        self.export_button.on_click(lambda e: self._export(e.client))
        self._rebuild_params()

    # -- what is shown ---------------------------------------------------------------------------

    def shown(self, session: Session | None, layers: SessionLayers | None) -> None:
        """Refresh the panel for the session the workbench now draws (None: just a task); an earlier message goes."""
        self.message.visible = False
        self.table.content = step_table(session)
        finished = session.finished() if session is not None else []
        drawn = [name for name in finished if layers is not None and name in layers.layers]
        self.step.options = tuple(finished) or (NO_STEP,)
        self.step.value = (drawn or finished or [NO_STEP])[-1]  # the step in focus: the last one drawn
        self._step_chosen(self.step.value)
        self.saved.options = self._saved_options()
        scene = self.wb.scene
        poses = {INITIAL: Pose(scene.q_initial, scene.object_initial), **(layers.poses() if layers is not None else {})}
        for name, message in (layers.errors if layers is not None else {}).items():
            self._say(f"Could not draw {name}", message, error=True)
        self.wb.pose_choice.offer(poses, INITIAL if np.array_equal(self.wb.q, scene.q_initial) else OTHER)
        if session is not None and session.folder != self._scratch:
            self.name.value = session.folder.name
        self._rebuild_params()

    def _say(self, title: str, body: str, error: bool = False) -> None:
        """A message in the panel and a notification in every tab."""
        color = "#d22" if error else "#2a6"
        self.message.content = f"<span style='color:{color}'>**{plain(title)}:**</span> {plain(body)}"
        self.message.visible = True
        notify_all(self.wb.server, title, body, error)

    def _saved_options(self) -> tuple[str, ...]:
        return tuple(list_sessions(self.sessions_dir)) or (NO_SESSIONS,)

    def _step_chosen(self, name: str) -> None:
        """Show a finished step's details and its layer alone."""
        session = self.wb.session
        if session is None or name not in session.finished():
            self.details.content = "*No step has run yet.*"
            return
        self.details.content = step_details(session, name)
        self.wb.focus_step(name)

    def _rebuild_params(self) -> None:
        """Inputs for the chosen step's parameters, starting at the values the current session used."""
        if self._params is not None:
            self._params.remove()
        step, session = step_named(self.rerun_step.value), self.wb.session
        used = session.record_of(step.name)["params"] if session is not None and step.name in session.finished() else {}
        with self._params_folder:
            self._params = ParamInputs(self.wb.server.gui, step, used)

    # -- load and save ---------------------------------------------------------------------------

    def _load_clicked(self, client: viser.ClientHandle | None) -> None:
        if self.saved.value == NO_SESSIONS:
            self._say("Nothing to load", f"{self.sessions_dir} holds no sessions yet", error=True)
        else:
            folder = self.sessions_dir / self.saved.value
            self.ask_unsaved(client, f"load the session {folder.name}", lambda: self.load(folder))

    def unsaved_steps(self) -> list[str]:
        """The steps of the scratch session shown that are not saved as they are (none when no scratch session is shown)."""
        session = self.wb.session
        return unsaved_steps(session.records, self._saved_records) if session is not None and session.folder == self._scratch else []

    def ask_unsaved(self, client: viser.ClientHandle | None, what: str, proceed: Callable[[], Any],
                    cancelled: Callable[[], None] | None = None) -> None:
        """Run `proceed` (which replaces the shown session) once unsaved steps are dealt with: with steps unsaved and a
        `client`, its tab is asked to save, keep (as sessions/<task>-unsaved-N), discard or cancel (`cancelled` runs);
        without a client they are kept, as closing keeps them."""
        steps = self.unsaved_steps()
        if client is None or not steps:
            proceed()
            return
        name = self.name.value.strip()

        def answer(choice: str) -> None:
            if choice == CANCEL or self._refuse_while_busy():
                if cancelled is not None:
                    cancelled()
                return
            if choice == SAVE:
                try:
                    self.save(name)
                except Exception as exc:  # e.g. the name is taken: said, and nothing is replaced
                    self._say("Not saved", error_text(exc), error=True)
                    if cancelled is not None:
                        cancelled()
                    return
            elif choice == DISCARD and self.wb.session is not None:
                self._saved_records = self.wb.session.records  # nothing left to keep: the scratch session just goes
            proceed()
        ask_unsaved(client, steps, what, name, unsaved_name(self.sessions_dir, self.wb.scene), answer)

    def load(self, folder: Path) -> bool:
        """Replay a saved session; a bad one shows its error and leaves the workbench as it was."""
        if self._refuse_while_busy():
            return False
        try:
            session = Session.open(folder)
        except Exception as exc:  # a bad session must never take the workbench down
            self._say("Could not load the session", error_text(exc), error=True)
            return False
        self.message.visible = False
        self.wb.show_session(session)
        self.scratch = None
        return True

    def save(self, name: str, overwrite: bool = False) -> Session:
        """Copy the current session into `sessions/<name>`; an existing folder is replaced only with `overwrite`."""
        if self.wb.session is None:
            raise RegraspError("nothing to save: run a step or load a session first")
        saved = save_copy(self.wb.session, self.sessions_dir / check_name(name), overwrite)
        if self.wb.session.folder == self._scratch:
            self._saved_records = self.wb.session.records
        self.saved.options = self._saved_options()
        self.saved.value = saved.folder.name
        return saved

    def _save_clicked(self, client: viser.ClientHandle) -> None:
        """Save under the name field; an existing folder is replaced only after the person confirms."""
        if self._refuse_while_busy():
            return
        try:
            name = check_name(self.name.value)
            if self.wb.session is not None and (self.sessions_dir / name).exists():
                self._say("Not saved", f"sessions/{name} already exists: confirm in the dialog to overwrite it")
                confirm_overwrite(client, self.sessions_dir / name, lambda: self._save_reporting(name, overwrite=True))
                return
            self._save_reporting(name, overwrite=False)
        except Exception as exc:  # a message in the GUI, never an exception in the callback
            self._say("Not saved", error_text(exc), error=True)

    def _save_reporting(self, name: str, overwrite: bool) -> None:
        try:
            saved = self.save(name, overwrite)
        except Exception as exc:  # e.g. the sessions folder is read-only or full
            self._say("Not saved", error_text(exc), error=True)
            return
        self._say("Saved", f"the session is in {saved.folder}")

    # -- runs ------------------------------------------------------------------------------------

    def run_next(self) -> threading.Thread | None:
        """Run the first step the current session has not finished."""
        done = set(self.wb.session.finished()) if self.wb.session is not None else set()
        pending = [s.name for s in PIPELINE if s.name not in done]
        if not pending:
            self._say("Nothing to run", "every step of the pipeline has run")
            return None
        return self.run_until(pending[0])

    def run_until(self, until: str) -> threading.Thread | None:
        """Run every unfinished step up to `until` in the background (into the scratch session)."""
        done = set(self.wb.session.finished()) if self.wb.session is not None else set()
        todo = [s for s in steps_until(until) if s.name not in done]
        if not todo:
            self._say("Nothing to run", f"every step up to {until} has run")
            return None

        def work() -> None:
            session = self._working_session()
            try:
                run_pipeline(session, until, None, progress_factory(self.progress, self.progress_text, todo))
            finally:
                self.wb.show_session(session)
        return self._start(work)

    def rerun(self, step: str, values: dict[str, Any]) -> threading.Thread | None:
        """Re-run from `step` with new parameters into a new session `<name>-rerun-N`; the current one stays intact.

        Later steps the current session had finished run again with the parameters they used."""
        session = self.wb.session
        if session is None:
            self._say("Nothing to re-run", "load a session or run a step first", error=True)
            return None
        try:
            base = check_name(self.name.value) if session.folder == self._scratch else session.folder.name
            step_named(step).make_params(values)  # the edited values in their declared ranges, before any folder is made
        except RegraspError as exc:
            self._say("Not re-run", str(exc), error=True)
            return None
        target = self.sessions_dir / free_name(self.sessions_dir, re.sub(r"-rerun-\d+$", "", base))
        order = [s.name for s in PIPELINE]
        until = order[max([order.index(step), *(order.index(n) for n in session.finished())])]
        params = {r["name"]: recorded_params(step_named(r["name"]), r["params"]) for r in session.records}
        params[step] = values

        def work() -> None:
            new = session.branch(target, before=step)
            todo = [s for s in steps_until(until) if s.name not in new.finished()]
            try:
                run_pipeline(new, until, params, progress_factory(self.progress, self.progress_text, todo))
            finally:
                self.wb.show_session(new)
                self.scratch = None
                self.saved.options = self._saved_options()
            self._say("Re-ran", f"from {step} into {target}; {session.folder} is unchanged")
        return self._start(work)

    def _working_session(self) -> Session:
        """The session runs write into: the scratch one, else a new scratch one (a copy of the loaded session)."""
        session = self.wb.session
        if session is not None and session.folder == self._scratch:
            return session
        if session is None:
            seed = whole(self.seed.value)
            if seed_problem(seed):  # refused before the scratch folder is made
                raise RegraspError(f"Seed: {seed_problem(seed)}")
            new = Session.create(scratch_folder(), self.wb.scene, seed)
        else:
            new = scratch_copy(session)
        self.scratch = new.folder
        self._saved_records = session.records if session is not None else None  # a copy's steps are saved where they came from
        return new

    @property
    def scratch(self) -> Path | None:
        """The session folder the GUI created; the only one runs write into."""
        return self._scratch

    @scratch.setter
    def scratch(self, folder: Path | None) -> None:
        """Replace the scratch session; the one replaced is deleted once its unsaved steps are kept (`discard_scratch`)."""
        if self._scratch is not None and self._scratch != folder:
            self._drop_scratch()
        self._scratch = folder

    def _drop_scratch(self) -> tuple[str, str, bool] | None:
        """Delete the scratch session once its unsaved steps are kept; what was said about them, if anything."""
        assert self._scratch is not None
        said = discard_scratch(self._scratch, self.sessions_dir, self._saved_records)
        if said is not None:
            self._say(*said)
            self.saved.options = self._saved_options()
        self._scratch, self._saved_records = None, None
        return said

    def close(self) -> str | None:
        """Stop a run still going (its workers), then delete the scratch session; where its unsaved steps were kept (or
        why they could not be), if there were any."""
        job = self.job
        if job is not None and job.is_alive():
            stop_pools(job)
            job.join(JOIN_SECONDS)
        said = self._drop_scratch() if self._scratch is not None else None
        return f"{said[0]}: {said[1]}" if said is not None else None

    def _start(self, work: Callable[[], None]) -> threading.Thread | None:
        """Run `work` in a background thread with the run buttons disabled and the progress bar shown."""
        with self._starting:  # two clicks at once start one run
            if self._refuse_while_busy():
                return None
            self.job = threading.Thread(target=lambda: self._run(work), daemon=True)
            for button in self._buttons:
                button.disabled = True
            self.progress.value, self.progress.visible = 0.0, True
            self.progress_text.content, self.progress_text.visible = "*starting…*", True
            self.message.visible = False
            self.job.start()
        return self.job

    def _run(self, work: Callable[[], None]) -> None:
        """A run's thread: `work`, its failure shown, then the buttons enabled again."""
        try:
            work()
        except Exception as exc:  # shown in the GUI; the workbench stays usable
            self._say("Run failed", error_text(exc), error=True)
        finally:
            for button in self._buttons:
                button.disabled = False
            self.progress.visible = self.progress_text.visible = False

    def busy(self) -> bool:
        """Whether a run is going (in another thread than the caller's)."""
        return self.job is not None and self.job.is_alive() and self.job is not threading.current_thread()

    def _refuse_while_busy(self) -> bool:
        busy = self.busy()
        if busy:
            self._say("Busy", "wait for the current run to finish", error=True)
        return busy

    # -- export ----------------------------------------------------------------------------------

    def _export(self, client: viser.ClientHandle) -> None:
        """Send what is shown to the browser as one self-contained HTML file."""
        name = f"{self.name.value.strip() or 'regrasp'}.html"
        client.send_file_download(name, scene_html(self.wb.server).encode(), save_immediately=True)
