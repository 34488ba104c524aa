"""Shared fixtures: a private cache folder (deleted when the tests end), a step's pools inline in a pytest-xdist worker,
the default scene and its collision model (built once)."""
from __future__ import annotations

import contextlib
import os

import pytest

from planner.core.paths import temporary_folder

if "REGRASP_CACHE" not in os.environ:  # a cache given in the environment is the user's, and stays
    os.environ["REGRASP_CACHE"] = str(temporary_folder("regrasp-test-cache-"))


@pytest.fixture(scope="session", autouse=True)
def one_process_per_test_worker():
    """Under pytest-xdist each core already runs a test worker: a step's pools run inline (cpu_budget 1) instead of
    forking processes that take the other worker's core. The tests of the forked paths set their own budget
    (test_motion_workers.py, test_nested_pools.py, test_orphans.py, test_session.py), and the command-line tests'
    subprocesses keep every core."""
    from planner.core.forked import cpu_budget

    with cpu_budget(1) if os.environ.get("PYTEST_XDIST_WORKER") else contextlib.nullcontext():
        yield


@pytest.fixture(scope="session")
def default_scene():
    from planner.model.task import load_task

    return load_task("default")


@pytest.fixture(scope="session")
def default_collision(default_scene):
    from planner.collision.checker import build_collision_model

    return build_collision_model(default_scene.robot, default_scene.environment)


@pytest.fixture(scope="module")
def browser():
    """Headless Debian chromium driven by playwright (software WebGL), without WebGL's multisampling: in software it
    took more than half of every frame's work, and the tests compare pixels, not smooth edges (the README picture keeps
    it: workbench/screenshot.py); skipped only when chromium is absent."""
    from playwright.sync_api import sync_playwright

    from workbench.screenshot import CHROMIUM, CHROMIUM_ARGS

    if not CHROMIUM.exists():
        pytest.skip("Debian chromium is not installed at /usr/bin/chromium (apt-get install chromium)")
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=[*CHROMIUM_ARGS, "--webgl-antialiasing-mode=none"])
        yield browser
        browser.close()


@pytest.fixture(scope="module")
def page(workbench, browser):
    """A page open on the test module's own `workbench` fixture (modules needing another page define their own)."""
    from test_workbench_browser import _open

    page = _open(workbench, browser)
    yield page
    page.close()
