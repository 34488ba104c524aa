"""The motion's HTML export keeps the playback's meaning: the phase label above the object goes through every phase the
motion stores, in time order, and the grasp, exchange and place keyframes are named in the scene."""
from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from sandbox import EXAMPLE

from planner.core.session import Session
from workbench import export
from workbench.layers.phases import phase_spans
from workbench.playback import MARKED, Playback


@pytest.mark.slow  # the example's whole session drawn and recorded frame by frame
def test_export_records_the_phase_labels_and_keyframes(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    folder = tmp_path / "example"
    shutil.copytree(EXAMPLE, folder)
    labels: list[str] = []
    draw = Playback.draw

    def recorded(self: Playback, i: int) -> int:
        i = draw(self, i)
        labels.append(self.label.text)
        return i

    monkeypatch.setattr(Playback, "draw", recorded)
    named: list[str] = []
    add_label = export.viser.SceneApi.add_label
    monkeypatch.setattr(export.viser.SceneApi, "add_label",
                        lambda self, name, text, **kw: (named.append(text), add_label(self, name, text, **kw))[1])
    page = export.session_html(folder)
    assert "__VISER_EMBED_DATA__" in page
    motion = Session.open(folder).result("motion")
    phases = [motion.phase_name(k) for k, _, _ in phase_spans(motion)]
    seen = [text.split(" · ")[0] for text in labels]
    runs = [name for k, name in enumerate(seen) if k == 0 or name != seen[k - 1]]
    assert runs == phases, f"the exported label went through {runs}, the motion's phases are {phases}"
    assert set(MARKED.values()) <= set(named), f"keyframes named in the export: {named}"
