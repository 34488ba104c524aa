"""Shared fixtures: a private cache folder, the default scene and its collision model (built once)."""
from __future__ import annotations

import os
import tempfile

import pytest

os.environ.setdefault("REGRASP_CACHE", tempfile.mkdtemp(prefix="regrasp-test-cache-"))


@pytest.fixture(scope="session")
def default_scene():
    from planner.task import load_task

    return load_task("default")


@pytest.fixture(scope="session")
def default_collision(default_scene):
    from planner.collision import build_collision_model

    return build_collision_model(default_scene.robot, default_scene.environment)
