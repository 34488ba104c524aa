"""The `regrasp` command line's headless commands (check, plan, suite, params, roadmap, grasps, bench) and how any
sub-command runs: every fault a user can meet ends in one line on stderr and an exit code, never a traceback.

The commands that open the workbench are added by `workbench.cli` (through `command_line(first=...)`), so that the
planner never imports the workbench."""
from __future__ import annotations

import logging
import signal
import sys
from collections.abc import Sequence

from planner import __version__
from planner.cli.arguments import AddCommands, CommandLine
from planner.cli.bench_commands import add_bench
from planner.cli.offline import add_grasps, add_roadmap
from planner.cli.plan import add_check, add_params, add_plan
from planner.cli.suite import add_suite
from planner.core.errors import RegraspError

HEADLESS = "Pick-and-place with two-hand regrasping: the planner's headless commands."
COMMANDS: tuple[AddCommands, ...] = (add_check, add_plan, add_suite, add_params, add_roadmap, add_grasps, add_bench)


def command_line(description: str = HEADLESS, epilog: str | None = None, first: Sequence[AddCommands] = ()) -> CommandLine:
    """The whole parser: the commands `first` adds, then the headless ones, each option with its help and default."""
    line = CommandLine(description, epilog)
    line.root.add_argument("--version", action="version", version=f"regrasp {__version__}")
    for add in (*first, *COMMANDS):
        add(line)
    return line


class _LineAboveBars(logging.Handler):
    """Prints regrasp's log lines (e.g. a cache entry recomputed) on their own line above the progress bars."""

    def emit(self, record: logging.LogRecord) -> None:
        from tqdm import tqdm

        tqdm.write(self.format(record), file=sys.stderr)


def main(argv: list[str] | None = None, line: CommandLine | None = None) -> int:
    """Run one sub-command of `line` (default: the headless command line)."""
    from planner.core.forked import Terminated, sigterm_unwinds

    p = (line or command_line()).root
    args = p.parse_args(argv)
    if args.command is None:
        p.print_help()
        return 0
    log = logging.getLogger("regrasp")
    if not any(isinstance(h, _LineAboveBars) for h in log.handlers):
        log.addHandler(_LineAboveBars(logging.INFO))  # found first: Python's last-resort stderr handler stays unused
    try:
        with sigterm_unwinds():
            return args.func(args)
    except RegraspError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # an I/O fault no step turned into a RegraspError: still one line
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2
    except Terminated:
        print("error: terminated (SIGTERM)", file=sys.stderr)
        return 128 + signal.SIGTERM
    except KeyboardInterrupt:
        print("error: interrupted", file=sys.stderr)
        return 130
