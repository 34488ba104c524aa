"""The `regrasp` command line: the planner's headless commands (`planner.cli`) with the ones that open the workbench
(workbench, replay, export, screenshot) added in front. The planner's parser knows nothing of the workbench; this
module, which imports both, is the entry point."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from planner.cli import main as headless
from planner.cli.arguments import Command, CommandLine, add_task
from planner.core.paths import PROJECT_ROOT

EXAMPLE_SESSION = PROJECT_ROOT / "sessions" / "default-example"
SCREENSHOT = PROJECT_ROOT / "assets" / "workbench.png"
DESCRIPTION = "Pick-and-place with two-hand regrasping: planner and workbench."
EPILOG = "Start with `regrasp workbench` and open the address it prints."


def _cmd_workbench(args: argparse.Namespace) -> int:
    from .app import run

    run(args.task, args.host, args.port)
    return 0


def _cmd_replay(args: argparse.Namespace) -> int:
    from .app import run

    run(None, args.host, args.port, session=Path(args.session))
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    from planner.core.errors import RegraspError
    from planner.motion.trajectory_file import FORMATS, output_path, write_trajectory

    if not (args.html or args.trajectory):
        raise RegraspError("export: give --html FILE, --trajectory FILE, or both")
    html = args.html and output_path(Path(args.html), "--html", (".html", ".htm"), args.force)
    trajectory = args.trajectory and output_path(Path(args.trajectory), "--trajectory", FORMATS, args.force)
    if trajectory:
        points = write_trajectory(Path(args.session), trajectory)
        print(f"wrote {trajectory} ({points} points)")
    if html:
        from .export import export_html

        export_html(Path(args.session), html)
        print(f"wrote {html}")
    return 0


def _cmd_screenshot(args: argparse.Namespace) -> int:
    from .screenshot import screenshot

    size = screenshot(Path(args.session), Path(args.out))
    print(f"wrote {args.out} ({size // 1024} kB)")
    return 0


def _add_server(command: Command) -> None:
    command.add("--host", default="127.0.0.1", help="address to serve on (0.0.0.0: every interface)")
    command.add("--port", type=int, default=8080, help="port to serve on; an error if it is in use")


def add_workbench_commands(line: CommandLine) -> None:
    """`regrasp workbench`, `replay`, `export` and `screenshot`."""
    w = line.command("workbench", "start the web workbench (viser) on a task", _cmd_workbench)
    add_task(w)
    _add_server(w)
    r = line.command("replay", "open the workbench on a saved session (nothing is recomputed)", _cmd_replay)
    r.add("session", metavar="SESSION", help="session folder")
    _add_server(r)
    e = line.command("export", "export a saved session as one self-contained HTML file, or its motion as a trajectory file",
                     _cmd_export)
    e.add("session", metavar="SESSION", help="session folder")
    e.add("--html", metavar="FILE", help="HTML file to write (.html)")
    e.add("--trajectory", metavar="FILE", help="trajectory file to write: .json (a ROS JointTrajectory and more) or .csv "
                                                "(docs/sessions.md)")
    e.add("--force", action="store_true", help="replace files that exist")
    s = line.command("screenshot", "picture the workbench replaying a session (the README's image), with headless chromium",
                     _cmd_screenshot)
    s.add("session", nargs="?", default=str(EXAMPLE_SESSION), metavar="SESSION", help="session folder")
    s.add("--out", default=str(SCREENSHOT), metavar="PNG", help="image to write")


def command_line() -> CommandLine:
    """Every `regrasp` command: the workbench's, then the planner's headless ones."""
    return headless.command_line(DESCRIPTION, EPILOG, first=[add_workbench_commands])


def main(argv: list[str] | None = None) -> int:
    """Run one `regrasp` sub-command (see `planner.cli.main.main`)."""
    return headless.main(argv, command_line())


if __name__ == "__main__":
    sys.exit(main())
