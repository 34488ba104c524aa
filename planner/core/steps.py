"""The step framework: each pipeline stage is a `Step` with declared inputs, parameters and result.

A step's `run(ctx)` is a function of the scene, the results of the steps it needs (and the
parameters they ran with), its frozen parameters and a seeded generator; it returns a `StepOutput`:
a frozen result dataclass (see `results.py`, with a `stats()` method giving its key figures) and,
separately, what the run measured (stage seconds), which goes to the session record, never into the
result. `pipeline.py` lists the steps in order.
"""
from __future__ import annotations

import dataclasses
import math
import zlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from planner.core.bounds import Bound, field_bound, field_choices
from planner.core.errors import InputError, RegraspError
from planner.core.results import MAX_DEPTH, check_nesting, parse_json, read_only

if TYPE_CHECKING:  # the task model (trimesh) is not loaded by the commands that do not read a task
    from planner.model.task import Scene

Progress = Callable[[float, str], None]


class StepFailed(RegraspError):
    """A step ran and was recorded, but its result says a stage kept nothing: the pipeline cannot go on."""

    def __init__(self, step: str, failure: str):
        super().__init__(f"step '{step}' failed: {failure}")
        self.step, self.failure = step, failure


def no_progress(fraction: float, message: str = "") -> None:
    """A progress callback that reports nowhere."""


@dataclass(frozen=True)
class StepContext:
    """What a step may use: nothing else passes between steps."""

    scene: Scene
    inputs: Mapping[str, Any]
    input_params: Mapping[str, Any]  # step name -> the frozen parameters that step of `inputs` ran with
    params: Any
    rng: np.random.Generator
    progress: Progress = no_progress


@dataclass(frozen=True)
class StepOutput:
    """What a step returns: its result, and apart from it what the run measured (for its session record only): the
    seconds of its stages, and whether the result was loaded from the user cache (its seconds are then not its cost)."""

    result: Any
    stage_seconds: tuple[float, ...] = ()
    cached: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "result", read_only(self.result))  # while it is built: the result as it will be shared


@dataclass(frozen=True)
class Step:
    """One pipeline stage."""

    name: str
    summary: str
    needs: tuple[str, ...]
    params: type
    result: type
    run: Callable[[StepContext], StepOutput]
    seed_name: str = ""  # the name its generator's seed is derived from (default: its own); steps sharing one draw alike
    recoverable: bool = False  # its failure leaves a later step a fallback: the pipeline goes on past it (see runner.py)
    retired: tuple[str, ...] = ()  # parameters it no longer has, which sessions saved before still record

    def recorded_params(self, recorded: Mapping[str, Any]) -> Any:
        """The parameters a session record gives (make_params), less the retired ones: a session saved before a
        parameter was renamed or removed still opens, its result made as its record says; running the step again takes
        today's parameter instead (its default, unless given)."""
        return self.make_params({k: v for k, v in recorded.items() if k not in self.retired})

    def seed(self, session_seed: int) -> int:
        """The seed of this step's generator in a session with this seed."""
        return step_seed(session_seed, self.seed_name or self.name)

    def make_params(self, values: Mapping[str, Any] | None = None) -> Any:
        """The step's parameters: defaults overridden by `values`, with unknown names refused."""
        values = dict(values or {})
        known = {f.name for f in dataclasses.fields(self.params)}
        unknown = set(values) - known
        if unknown:
            names = ", ".join(sorted(known)) or "none"
            raise RegraspError(f"step '{self.name}' has no parameter {', '.join(sorted(unknown))} (parameters: {names})")
        defaults = self.params()
        bounds = param_bounds(self.params)
        choices = {f.name: field_choices(f) for f in dataclasses.fields(self.params)}
        for name, value in values.items():
            expected = type(getattr(defaults, name))
            accepted = (int, float) if expected is float else expected  # a float parameter takes a whole number too
            if not isinstance(value, accepted) or (expected is not bool and isinstance(value, bool)):
                raise RegraspError(f"step '{self.name}': parameter {name} expects {expected.__name__}, got {value!r}")
            if isinstance(value, float) and not math.isfinite(value):
                raise RegraspError(f"step '{self.name}': parameter {name} expects a finite number, got {value!r}")
            out_of_range = bounds[name].problem(value, "expects a value") if name in bounds else choice_problem(choices, name, value)
            if out_of_range:  # checked before float(): a huge whole number is out of range, never an OverflowError
                raise RegraspError(f"step '{self.name}': parameter {name} {out_of_range}")
            values[name] = expected(value)
        params = dataclasses.replace(defaults, **values)
        problem = params.problem() if hasattr(params, "problem") else ""  # a step's own constraints between values
        if problem:
            raise RegraspError(f"step '{self.name}': parameter {problem}")
        return params


def choice_problem(choices: Mapping[str, tuple[str, ...]], name: str, value: Any) -> str:
    """What is wrong with a name parameter's value ('' when the parameter declares no choices or the value is one)."""
    options = choices.get(name, ())
    return f"expects one of {', '.join(options)}, got {value!r}" if options and value not in options else ""


def param_bounds(params: type) -> dict[str, Bound]:
    """The range and unit each numeric parameter of a step's parameter dataclass declares (see bounds.py)."""
    return {f.name: bound for f in dataclasses.fields(params) if (bound := field_bound(f)) is not None}


def step_seed(seed: int, name: str) -> int:
    """The seed a step's generator gets: derived from the session seed and the step's name."""
    return int(np.random.SeedSequence([seed, zlib.crc32(name.encode())]).generate_state(1)[0])


def parse_assignment(text: str) -> tuple[str, str, Any]:
    """'step.param=value' from the command line; the value is read as JSON when it parses, else a string."""
    import json

    key, sep, raw = text.partition("=")
    step, dot, param = key.partition(".")
    if not sep or not dot or not step or not param:
        raise RegraspError(f"--set expects step.param=value, got '{text}'")
    try:
        value = parse_json(raw)
    except json.JSONDecodeError:
        value = raw
    except RecursionError as exc:
        raise InputError("--set", key, f"nested deeper than Python can parse; expected at most {MAX_DEPTH} levels") from exc
    check_nesting(value, "--set", key)
    return step, param, value
