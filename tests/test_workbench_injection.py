"""Text from files, sessions, results and errors never becomes markup: in the workbench (a real browser replays a crafted
session and shows a rejected one), in the exported HTML and in a suite's report.html."""
from __future__ import annotations

import html
import json
import time
from collections.abc import Iterator
from html.parser import HTMLParser
from pathlib import Path
from typing import Any

import pytest
from playwright.sync_api import Browser, Page
from test_workbench_browser import EXAMPLE, VIEWPORT, _free_port, _wait_for

from planner.core.plain_text import plain
from planner.core.session import MANIFEST, Session
from planner.model.task import load_task
from planner.suite.report import report_html
from planner.suite.spec import load_suite
from workbench.app import Workbench
from workbench.export import session_html
from workbench.step_table import step_details, step_table

PAYLOAD = "<iframe style=\"display:none\" srcdoc=\"<script>parent.document.title='PWNED'</script>\"></iframe>"
MARKUP = [PAYLOAD, "<img src=x onerror=alert(1)>", "![x](http://evil.example/t.png)", "[a](javascript:alert(1))",
          "**bold** `code` | cell\n# heading\n<b>", "http://evil.example &amp; &#60;"]


def _crafted(folder: Path, change: Any) -> Path:
    """The example's first step as a session at `folder`, its manifest changed by `change`."""
    Session.open(EXAMPLE).branch(folder, before="pick_grasps")
    manifest = json.loads((folder / MANIFEST).read_text())
    change(manifest)
    (folder / MANIFEST).write_text(json.dumps(manifest))
    return folder


def _describe(text: str) -> Any:
    return lambda manifest: manifest["task"].__setitem__("description", text)


@pytest.mark.parametrize("text", MARKUP)
def test_plain_text_is_shown_as_written(text: str) -> None:
    shown = plain(text)
    assert not set(shown) & set("<>`*[]|!\n"), shown
    assert html.unescape(shown) == text.replace("\n", " ")


def test_step_table_and_details_escape_recorded_figures(tmp_path: Path) -> None:
    def change(manifest: dict) -> None:
        manifest["steps"][0]["stats"] |= {"picking_arm": PAYLOAD, PAYLOAD: 1}  # a key figure of the table, a detail
    session = Session.open(_crafted(tmp_path / "s", change))
    table, details = step_table(session), step_details(session, "arms")
    assert "<" not in table + details
    assert f"picking_arm={PAYLOAD[:15]}…" in html.unescape(table)  # cut to fit the table, then escaped
    assert f"| {PAYLOAD} | 1 |" in html.unescape(details) and f"| picking_arm | {PAYLOAD} |" in html.unescape(details)


class _Tags(HTMLParser):
    """Every start tag and every link of a page."""

    def __init__(self) -> None:
        super().__init__()
        self.tags: set[str] = set()
        self.hrefs: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.add(tag)
        self.hrefs += [v or "" for k, v in attrs if k == "href"]


def _tags(page: str) -> _Tags:
    parser = _Tags()
    parser.feed(page)
    return parser


def test_report_shows_crafted_suite_results_as_text() -> None:
    spec = load_suite("default")
    result = {"id": PAYLOAD, "success": False, "failed_step": PAYLOAD, "failed_stage": PAYLOAD, "message": PAYLOAD,
              "session": "javascript:alert(1)//", "initial": [0.5, 0.2, 0.8], "final": [0.5, -0.2, 0.8],
              "initial_region": PAYLOAD, "final_region": PAYLOAD, "double_grasps": PAYLOAD, "motion_duration": None,
              "path_length": None}
    rate = {"tasks": 1, "succeeded": 0, "success_rate": 0.0}
    data = {"results": [result], "seconds": {PAYLOAD: {"median": 1.0, "p95": 2.0}}, "by_stage": {PAYLOAD: 1},
            "by_initial_region": {PAYLOAD: rate}, "by_final_region": {PAYLOAD: rate}, "by_object": {PAYLOAD: rate},
            "finished": PAYLOAD, "tasks": PAYLOAD, "succeeded": PAYLOAD, "success_rate": 0.0, "until": PAYLOAD,
            "wall_seconds": 1.0}
    page = report_html(data, spec, load_task(spec.base_task).environment, "out")
    parsed = _tags(page)
    assert parsed.tags <= {"html", "head", "meta", "title", "style", "body", "h1", "h2", "p", "span", "b", "div", "figure",
                           "figcaption", "svg", "text", "rect", "line", "circle", "polygon", "table", "tr", "th", "td", "a",
                           "code"}, parsed.tags
    assert parsed.hrefs and all(":" not in href for href in parsed.hrefs), parsed.hrefs  # relative links only
    assert PAYLOAD in html.unescape(page)  # shown, as text


def test_exported_html_carries_no_markup_from_the_session(tmp_path: Path) -> None:
    page = session_html(_crafted(tmp_path / "s", _describe(PAYLOAD)))
    assert "<iframe" not in page and "PWNED" not in page


@pytest.fixture(scope="module")
def replayed(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Workbench]:
    """The workbench replaying a session whose task description is a script; a rejected session beside it."""
    root = tmp_path_factory.mktemp("injection")
    folder = _crafted(root / "sessions" / "crafted", _describe(PAYLOAD))
    _crafted(root / "sessions" / "rejected", lambda manifest: manifest.__setitem__("robot_spec_name", PAYLOAD))
    wb = Workbench(None, "127.0.0.1", _free_port(), session=folder, sessions_dir=root / "sessions")
    yield wb
    wb.close()


@pytest.fixture(scope="module")
def page(replayed: Workbench, browser: Browser) -> Iterator[Page]:
    page = browser.new_page(viewport=VIEWPORT)
    page.goto(replayed.url)
    page.get_by_text("Collisions:").wait_for(timeout=60_000)
    yield page
    page.close()


def _unchanged(wb: Workbench, page: Page, title: str, finished: list[str]) -> None:
    time.sleep(1.0)  # a script would have run by now
    assert page.title() == title != "PWNED"
    assert page.locator("iframe").count() == 0
    assert wb.session_panel.job is None and wb.session is not None and wb.session.finished() == finished


@pytest.mark.browser
def test_a_replayed_description_is_shown_as_text(replayed: Workbench, page: Page, browser: Browser) -> None:
    clean = browser.new_page()
    try:
        clean.goto(replayed.url)
        title = clean.title()
    finally:
        clean.close()
    _unchanged(replayed, page, title, ["arms"])
    page.get_by_text("parent.document.title", exact=False).first.wait_for(timeout=20_000)  # the description, as text


@pytest.mark.browser
def test_a_rejected_session_quoting_a_script_is_shown_as_text(replayed: Workbench, page: Page) -> None:
    title, session = page.title(), replayed.session
    assert not replayed.session_panel.load(replayed.session_panel.sessions_dir / "rejected")  # what "Load" does
    page.get_by_text("Could not load the session").first.wait_for(timeout=20_000)
    assert _wait_for(lambda: page.get_by_text("robot_spec_name", exact=False).count() > 0)
    _unchanged(replayed, page, title, ["arms"])
    assert replayed.session is session
