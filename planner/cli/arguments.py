"""The `regrasp` parser as it is built: sub-commands and their options, each option's help showing its default, every
parser and option kept by command name; and the argument types the commands share (TASK, SUITE, --seed, counts)."""
from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from planner.core.errors import InputError

Handler = Callable[[argparse.Namespace], int]


class Command:
    """One (sub-)command's parser and the options added to it through `add` (each with its help and default)."""

    def __init__(self, name: str, parser: argparse.ArgumentParser):
        self.name, self.parser = name, parser
        self.arguments: list[argparse.Action] = []

    def add(self, *names: str, help: str, within: Any = None, **kw: Any) -> argparse.Action:
        """`parser.add_argument` (or the mutually exclusive group `within`'s), its help ending in its default unless
        that is empty (None, False) or the help names it already."""
        if kw.get("default") not in (None, False) and "%(default)" not in help:
            help += " (default: %(default)s)"
        action = (within or self.parser).add_argument(*names, help=help, **kw)
        self.arguments.append(action)
        return action


class Parser(argparse.ArgumentParser):
    """An argument parser (and its sub-commands' parsers) whose epilog may be a function, called only when the help is
    printed: `regrasp plan`'s lists the pipeline's steps, which load the whole planner (seconds), and a command that
    does not print that help need not load it."""

    @property
    def epilog(self) -> str | None:  # type: ignore[override]
        return self._epilog() if callable(self._epilog) else self._epilog

    @epilog.setter
    def epilog(self, text: str | Callable[[], str] | None) -> None:
        self._epilog = text


class CommandLine:
    """The `regrasp` parser and its sub-commands by full name (e.g. 'plan', 'bench collision'; '' is the top level)."""

    def __init__(self, description: str, epilog: str | None = None):
        self.root = Parser(prog="regrasp", formatter_class=argparse.RawDescriptionHelpFormatter, description=description,
                           epilog=epilog)
        self.commands = {"": Command("", self.root)}
        self._subparsers = {"": self.root.add_subparsers(dest="command", metavar="COMMAND")}

    def command(self, name: str, text: str, handler: Handler | None = None, within: str = "", **kw: Any) -> Command:
        """A sub-command of `within` (a group made by `group`, or the top level) run by `handler`: `text` is its one-line
        help and, capitalised, its description."""
        parser = self._subparsers[within].add_parser(name, help=text, description=text[0].upper() + text[1:] + ".",
                                                     formatter_class=argparse.RawDescriptionHelpFormatter, **kw)
        if handler is not None:
            parser.set_defaults(func=handler)
        command = self.commands[f"{within} {name}".strip()] = Command(f"{within} {name}".strip(), parser)
        return command

    def group(self, name: str, text: str, dest: str, metavar: str) -> Command:
        """A command whose sub-commands (made with `command(..., within=name)`) say what it does, e.g. `bench collision`."""
        command = self.command(name, text)
        self._subparsers[name] = command.parser.add_subparsers(dest=dest, required=True, metavar=metavar)
        return command


AddCommands = Callable[[CommandLine], None]


def positive_int(text: str) -> int:
    """argparse type of a count: an integer of at least 1."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number of at least 1, got '{text}'")
    return value


def seed_argument(text: str) -> int:
    """argparse type of --seed: a whole number in the range a session file accepts (checked before any folder is made)."""
    from planner.core.bounds import seed_problem

    try:
        value = int(text)
    except ValueError:
        value = text
    problem = seed_problem(value)
    if problem:
        raise argparse.ArgumentTypeError(problem)
    return value


def task_argument(text: str) -> Path:
    """argparse type of TASK: a task file, or a name in assets/tasks/ ("did you mean" and the names otherwise)."""
    from planner.model.task import find_task

    try:
        return find_task(text)
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from exc


def suite_argument(text: str) -> Path:
    """argparse type of SUITE: a suite file, or a name in assets/suites/."""
    from planner.suite.spec import find_suite

    try:
        return find_suite(text)
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from exc


def add_task(command: Command, default: str | None = "default", note: str = "") -> None:
    """The TASK positional, the same in every command that takes a task."""
    command.add("task", nargs="?", default=default, type=task_argument, metavar="TASK",
                help=f"a task file, or the name of one in assets/tasks/ (e.g. default, baxter){note}")


def add_json(command: Command, what: str) -> None:
    """--json FILE: the command's figures also written as JSON."""
    command.add("--json", metavar="FILE", help=f"also write {what} to this JSON file")


def write_json(path: Path, data: dict) -> None:
    """Write a command's figures as indented JSON (atomically: a reader never sees half a file)."""
    from planner.core.results import atomic_write_text

    atomic_write_text(path, json.dumps(data, indent=2))
