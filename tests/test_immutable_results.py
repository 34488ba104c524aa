"""Step results are immutable: every field of every step result of the example session is a scalar, a tuple, a
read-only mapping or array, or a frozen dataclass, all the way down; and they save as they were written."""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from planner.core.results import FrozenDict, frozen_json, save_result
from planner.core.session import Session

EXAMPLE = Path(__file__).resolve().parent.parent / "sessions" / "default-example"


def _mutable(value, where: str) -> list[str]:
    """Where in `value` something can be changed in place."""
    if isinstance(value, np.ndarray):
        return [] if not value.flags.writeable else [where]
    if isinstance(value, FrozenDict):
        return [w for k, v in value.items() for w in _mutable(v, f"{where}.{k}")]
    if isinstance(value, (tuple, frozenset)):
        return [w for i, v in enumerate(value) for w in _mutable(v, f"{where}[{i}]")]
    if dataclasses.is_dataclass(value) and type(value).__dataclass_params__.frozen:
        return [w for f in dataclasses.fields(value) for w in _mutable(getattr(value, f.name), f"{where}.{f.name}")]
    if value is None or isinstance(value, (bool, int, float, str, np.generic)):
        return []
    return [f"{where} ({type(value).__name__})"]


@pytest.fixture(scope="module")
def example():
    return Session.open(EXAMPLE)


def test_every_field_of_every_step_result_is_immutable(example):
    steps = example.finished()
    assert "motion" in steps
    found = [w for name in steps for w in _mutable(example.result(name), name)]
    assert not found, f"mutable fields: {found[:5]}"


def test_a_loaded_result_saves_as_it_was_written(example, tmp_path):
    for name in example.finished():
        save_result(example.result(name), tmp_path, name)
        assert json.loads((tmp_path / f"{name}.json").read_text()) == json.loads((EXAMPLE / f"{name}.json").read_text()), name


def test_frozen_json_refuses_changes():
    data = frozen_json({"a": [1, {"b": [2.0]}], "c": np.zeros(2)})
    assert data == {"a": (1, {"b": (2.0,)}), "c": data["c"]} and isinstance(data["a"][1], FrozenDict)
    for change in (lambda: data.__setitem__("d", 1), lambda: data["a"][1].update(b=3), lambda: data.pop("a"),
                   lambda: data.setdefault("d", 1), lambda: data.clear()):
        with pytest.raises(TypeError):
            change()
    with pytest.raises(ValueError):
        data["c"][0] = 1.0
    assert json.loads(json.dumps(data, default=list)) == {"a": [1, {"b": [2.0]}], "c": [0.0, 0.0]}


def test_the_scene_poses_and_configurations_are_read_only(example):
    scene = example.scene
    for name in ("object_initial", "object_final", "q_initial", "q_final"):
        assert not getattr(scene, name).flags.writeable, name
