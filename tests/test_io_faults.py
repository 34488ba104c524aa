"""Output faults (no permission, read-only file system, full disk) end in one message naming the folder and the cause,
exit 2, and leave no temporary file; the steps finished before stay readable.

The tests run as root, where file modes do not stop writes: the permission case drops the capabilities that
override them (setpriv), and the read-only and full-disk cases run in a private mount namespace (unshare) on a
small tmpfs, which vanishes with it. Each is skipped, saying why, only where the machine cannot do that.
"""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from sandbox import EXAMPLE, cli_env, one_error_line, regrasp, snapshot

DROP_DAC = ("setpriv", "--bounding-set=-dac_override,-dac_read_search,-fowner")
FREE_BYTES = 8192  # left free on the full disk: less than the grasp_configs step writes

DRIVER = r'''
import json, os, subprocess, sys
from pathlib import Path

mnt, scenario, example = Path(sys.argv[1]), sys.argv[2], sys.argv[3]


def cli(*args):
    run = subprocess.run([sys.executable, "-m", "workbench.cli", *args], capture_output=True, text=True)
    return {"code": run.returncode, "stderr": run.stderr}


out = {}
if scenario == "read-only":
    (mnt / "out").mkdir()
    subprocess.run(["mount", "-o", "remount,ro", str(mnt)], check=True)
    out["plan"] = cli("plan", "default", "--out", str(mnt / "out" / "s"), "--until", "arms")
    out["export"] = cli("export", example, "--html", str(mnt / "out" / "x.html"))
else:  # full: a session with three finished steps on a disk with FREE bytes left
    from planner.core.session import Session
    from workbench.session_store import save_copy

    session = Session.open(example).branch(mnt / "s", before="grasp_configs")
    fd = os.open(mnt / "filler", os.O_WRONLY | os.O_CREAT)
    try:
        while True:
            os.write(fd, bytes(65536))
    except OSError:
        pass
    os.close(fd)
    os.truncate(mnt / "filler", os.stat(mnt / "filler").st_size - int(sys.argv[4]))
    out["plan"] = cli("plan", "default", "--out", str(mnt / "s"), "--resume", "--until", "grasp_configs")
    try:
        save_copy(session, mnt / "sessions" / "saved")
        out["save"] = "saved"
    except Exception as exc:
        out["save"] = f"{type(exc).__name__}: {exc}"
    out["finished"] = Session.open(mnt / "s").finished()
out["files"] = sorted(str(p.relative_to(mnt)) for p in mnt.rglob("*"))
print(json.dumps(out))
'''


def _usable(command: list[str]) -> bool:
    try:
        return subprocess.run(command, capture_output=True, timeout=60, check=False).returncode == 0
    except (OSError, subprocess.TimeoutExpired):
        return False


def _in_tmpfs(tmp_path: Path, size: str, *args: str) -> dict:
    """Run the driver on a fresh tmpfs of `size` in a private mount namespace; its JSON report."""
    if not shutil.which("unshare") or not _usable(["unshare", "--mount", "--propagation", "private", "sh", "-c",
                                                   f"mount -t tmpfs -o size=64k tmpfs {tmp_path}"]):
        pytest.skip("this machine cannot mount a tmpfs in a private mount namespace (unshare --mount; needs CAP_SYS_ADMIN)")
    driver = tmp_path / "driver.py"
    driver.write_text(DRIVER)
    mnt = tmp_path / "mnt"
    mnt.mkdir()
    script = f'mount -t tmpfs -o size={size} tmpfs "$1" && shift && exec "$@"'
    run = subprocess.run(["unshare", "--mount", "--propagation", "private", "sh", "-c", script, "sh", str(mnt),
                          sys.executable, str(driver), str(mnt), *args], capture_output=True, text=True, timeout=900, env=cli_env(),
                         check=False)
    assert run.returncode == 0, run.stderr
    return json.loads(run.stdout.splitlines()[-1])


def _refused(result: dict, folder: Path, cause: str) -> str:
    assert result["code"] == 2, result["stderr"]
    line = one_error_line(result["stderr"])
    assert str(folder) in line and cause in line, line
    return line


@pytest.mark.slow
def test_out_folder_without_write_permission(tmp_path: Path) -> None:
    probe = tmp_path / "probe"
    probe.mkdir(mode=0o555)
    if not shutil.which("setpriv") or _usable([*DROP_DAC, "touch", str(probe / "x")]):
        pytest.skip("cannot drop the capabilities that let root write into a mode-555 folder (setpriv --bounding-set)")
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o555)
    before = snapshot(tmp_path)
    run = regrasp("plan", "default", "--out", str(locked / "s"), "--until", "arms", prefix=DROP_DAC)
    _refused({"code": run.returncode, "stderr": run.stderr}, locked / "s", "Permission denied [EACCES]")
    assert snapshot(tmp_path) == before


@pytest.mark.slow
def test_read_only_file_system(tmp_path: Path) -> None:
    report = _in_tmpfs(tmp_path, "1m", "read-only", str(EXAMPLE))
    mnt = tmp_path / "mnt"
    _refused(report["plan"], mnt / "out" / "s", "Read-only file system [EROFS]")
    _refused(report["export"], mnt / "out", "Read-only file system [EROFS]")
    assert report["files"] == ["out"]


@pytest.mark.slow
def test_full_disk_keeps_the_finished_steps_and_no_temporary_file(tmp_path: Path) -> None:
    report = _in_tmpfs(tmp_path, "2m", "full", str(EXAMPLE), str(FREE_BYTES))
    mnt = tmp_path / "mnt"
    _refused(report["plan"], mnt / "s", "No space left on device [ENOSPC]")
    assert report["finished"] == ["arms", "pick_grasps", "place_grasps"]
    assert report["save"].startswith("OutputError: ") and "[ENOSPC]" in report["save"] and str(mnt / "sessions") in report["save"]
    steps = [f"{s}.{e}" for s in ("arms", "pick_grasps", "place_grasps") for e in ("npz", "json")]
    session_files = sorted(f"s/{n}" for n in ["session.json", "task_meshes.npz"] + steps)
    assert report["files"] == sorted(["filler", "s", "sessions", *session_files]), "a temporary or staging file was left"
