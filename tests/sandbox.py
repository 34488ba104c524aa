"""Helpers for tests that treat sessions and caches as hostile input: example copies, file-tree snapshots, the CLI, mounts."""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

from planner.core.paths import PROJECT_ROOT
from planner.core.session import MANIFEST

EXAMPLE = PROJECT_ROOT / "sessions" / "default-example"
ESCAPE = "../" * 24  # from any folder of a realistic depth, enough `..` to reach the root


def copy_example(target: Path) -> Path:
    """A copy of the example session at `target` (the example itself is never touched)."""
    shutil.copytree(EXAMPLE, target)
    return target


def read_manifest(folder: Path) -> dict[str, Any]:
    return json.loads((folder / MANIFEST).read_text())


def write_manifest(folder: Path, manifest: dict[str, Any]) -> None:
    (folder / MANIFEST).write_text(json.dumps(manifest))


def escaping(target: Path) -> str:
    """A relative name that leaves any folder and lands on the absolute path `target`."""
    return ESCAPE + str(target).lstrip("/")


def snapshot(root: Path, skip: tuple[Path, ...] = ()) -> dict[str, str]:
    """Every entry under `root` (subtrees in `skip` left out) -> a digest of its content, link target or 'dir'."""
    out: dict[str, str] = {}
    skipped = {p.resolve() for p in skip}
    for dirpath, dirnames, filenames in os.walk(root):
        here = Path(dirpath)
        dirnames[:] = [d for d in dirnames if (here / d).resolve() not in skipped]
        for name in dirnames:
            out[str((here / name).relative_to(root))] = "dir"
        for name in filenames:
            p = here / name
            rel = str(p.relative_to(root))
            out[rel] = f"link:{os.readlink(p)}" if p.is_symlink() else hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def cli_env(**extra: str) -> dict[str, str]:
    """The environment a `regrasp` subprocess runs in: this source tree first on the path."""
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(PROJECT_ROOT), os.environ.get("PYTHONPATH", "")]), **extra}


def regrasp(*args: str, prefix: tuple[str, ...] = (), timeout: float = 600, **env: str) -> subprocess.CompletedProcess:
    """Run `regrasp <args>` as a user would (optionally under a wrapper such as setpriv), capturing its output."""
    return subprocess.run([*prefix, sys.executable, "-m", "workbench.cli", *args], capture_output=True, text=True, check=False,
                          timeout=timeout, env=cli_env(**env), cwd=PROJECT_ROOT)


def one_error_line(stderr: str) -> str:
    """The single `error:` line of a failed run (asserting there is exactly one and no traceback)."""
    assert "Traceback" not in stderr, stderr
    lines = [line for line in stderr.splitlines() if line.startswith("error:")]
    assert len(lines) == 1, stderr
    return lines[0]


def forbid(monkeypatch: Any, target: str) -> None:
    """Make the function at `target` ('module.name') raise: where a cache must serve, its builder may not run."""
    def forbidden(*args: Any, **kwargs: Any) -> Any:
        raise AssertionError(f"{target} ran: the cache should have served this")

    monkeypatch.setattr(target, forbidden)
