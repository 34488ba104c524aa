"""Temporary folders (a workbench's scratch session, the tests' private cache) are gone once the process that made
them exits, even when nothing closed them; a child forked from it exiting removes nothing."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from sandbox import cli_env

from planner.core.paths import PROJECT_ROOT

MAKE_AND_FORK = """
import os, sys
from workbench.session_store import scratch_folder
folder = scratch_folder().parent
print(folder, flush=True)
pid = os.fork()
if pid == 0:
    sys.exit(0)  # a forked child's exit runs the handlers it inherited
os.waitpid(pid, 0)
print(folder.exists(), flush=True)
"""


def _env(tmp: Path) -> dict[str, str]:
    """This tree's environment with temporary folders made under `tmp` and no cache named (the tests make their own)."""
    return {k: v for k, v in cli_env(TMPDIR=str(tmp)).items() if k != "REGRASP_CACHE"}


@pytest.mark.slow
def test_a_scratch_session_folder_is_removed_at_exit_not_at_a_childs(tmp_path: Path) -> None:
    run = subprocess.run([sys.executable, "-c", MAKE_AND_FORK], capture_output=True, text=True, timeout=120, env=_env(tmp_path),
                         cwd=PROJECT_ROOT, check=False)
    assert run.returncode == 0, run.stderr
    folder, alive = run.stdout.split()
    assert Path(folder).parent == tmp_path and alive == "True", run.stdout
    assert not Path(folder).exists(), "the scratch session outlived the workbench's process"


def test_the_tests_private_cache_is_removed_when_they_end(tmp_path: Path) -> None:
    one_test = "tests/test_docs.py::test_readme_is_a_short_guide"
    run = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", one_test], capture_output=True, text=True,
                         timeout=300, env=_env(tmp_path), cwd=PROJECT_ROOT, check=False)
    assert run.returncode == 0, run.stdout + run.stderr
    assert os.listdir(tmp_path) == [], os.listdir(tmp_path)
