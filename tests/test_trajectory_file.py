"""`regrasp export SESSION --trajectory FILE`: the motion as JSON (a ROS JointTrajectory and more) or CSV, read back here
with the json and csv modules and compared with motion.npz and the robot model as pinocchio loads it."""
from __future__ import annotations

import csv
import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from sandbox import EXAMPLE, cli_env, copy_example, one_error_line

from planner.core.results import load_result, save_result
from planner.core.session import Session
from planner.motion.result import PHASES, Motion

pytestmark = pytest.mark.slow  # each test runs `regrasp export` in a subprocess from a fresh folder


def export(cwd: Path, *args: str) -> subprocess.CompletedProcess:
    """`regrasp export` run from `cwd` (a fresh folder) with an empty cache in it."""
    return subprocess.run([sys.executable, "-m", "workbench.cli", "export", *args], capture_output=True, text=True, timeout=600,
                          cwd=cwd, env=cli_env(REGRASP_CACHE=str(cwd / "cache")), check=False)


@pytest.fixture(scope="module")
def model_joints() -> list[str]:
    """The example robot's joint names in q order, from pinocchio's model of the session's robot (1-DoF joints)."""
    model = Session.open(EXAMPLE).scene.robot.model
    assert model.nq == model.njoints - 1
    return [model.names[j] for j in range(1, model.njoints)]


@pytest.fixture(scope="module")
def npz() -> dict[str, np.ndarray]:
    with np.load(EXAMPLE / "motion.npz") as z:
        return {k: z[k] for k in z.files}


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Both formats written by the command line from a fresh folder with an empty cache."""
    folder = tmp_path_factory.mktemp("fresh")
    for name in ("t.json", "t.csv"):
        run = export(folder, str(EXAMPLE), "--trajectory", name)
        assert run.returncode == 0, run.stderr
        assert run.stdout.strip() == f"wrote {name} ({len(np.load(EXAMPLE / 'motion.npz')['t'])} points)"
    return folder


def test_json_is_a_joint_trajectory_with_the_samples_of_motion_npz(written: Path, model_joints: list[str], npz: dict) -> None:
    data = json.loads((written / "t.json").read_text())
    assert len(data["joint_names"]) == 49 and data["joint_names"] == model_joints
    points = data["points"]
    assert np.array_equal(np.array([p["positions"] for p in points]), npz["q"])
    stamps = [p["time_from_start"] for p in points]
    assert all(set(s) == {"sec", "nanosec"} and 0 <= s["nanosec"] < 10**9 for s in stamps)
    assert np.abs(np.array([s["sec"] + s["nanosec"] * 1e-9 for s in stamps]) - npz["t"]).max() < 1e-9
    assert data["time"] == npz["t"].tolist()
    assert data["phase"] == [PHASES[p] for p in npz["phase"]]
    arms = json.loads((EXAMPLE / "motion.json").read_text())["arms"]
    assert data["holder"] == [arms[h] if h >= 0 else None for h in npz["holder"]]
    xyz = np.array([[p["position"][k] for k in "xyz"] for p in data["object_pose"]])
    assert np.array_equal(xyz, npz["object_pose"][:, :3, 3])
    quat = np.array([[p["orientation"][k] for k in "wxyz"] for p in data["object_pose"]])
    rotations = np.array([pin.Quaternion(*q).normalized().toRotationMatrix() for q in quat])
    assert np.abs(rotations - npz["object_pose"][:, :3, :3]).max() < 1e-9
    assert list(data["keyframes"].values()) == npz["keyframes"].tolist()


def test_velocities_and_accelerations_are_the_timed_trajectorys(written: Path, npz: dict) -> None:
    """The stored velocities and accelerations, checked against the positions alone: between two samples dt apart each
    joint's acceleration stays within +-amax, so q and v move as the first sample's v and a say to within amax dt^2 and
    2 amax dt (exactly where no breakpoint falls between them); and within the session's limits."""
    points = json.loads((written / "t.json").read_text())["points"]
    v, a = np.array([p["velocities"] for p in points]), np.array([p["accelerations"] for p in points])
    assert np.array_equal(v, npz["qd"]) and np.array_equal(a, npz["qdd"])
    session = Session.open(EXAMPLE)
    params = session.record_of("motion")["params"]
    vmax = np.minimum(session.scene.robot.model.velocityLimit, params["max_velocity"])
    amax = params["max_acceleration"]
    assert np.all(np.abs(v) <= vmax * (1 + 1e-9)) and np.all(np.abs(a) <= amax * (1 + 1e-9))
    q, t = npz["q"], npz["t"]
    dt = t[1:, None] - t[:-1, None]
    dq = q[1:] - (q[:-1] + v[:-1] * dt + 0.5 * a[:-1] * dt**2)
    dv = v[1:] - (v[:-1] + a[:-1] * dt)
    assert np.all(np.abs(dq) <= amax * dt**2 + 1e-9) and np.all(np.abs(dv) <= 2 * amax * dt + 1e-9)
    exact = (np.abs(dq).max(axis=1) < 1e-9) & (np.abs(dv).max(axis=1) < 1e-9)  # no breakpoint between the two samples
    assert exact.mean() > 0.6  # 0.68 here; 0.52 or less with accelerations a sample late, velocities a sample late or by
    # finite differences
    assert np.allclose(v[1:-1][exact[1:] & exact[:-1]], ((q[2:] - q[:-2]) / (t[2:, None] - t[:-2, None]))[exact[1:] & exact[:-1]],
                       atol=amax * (t[1] - t[0]))
    assert not v[0].any() and not v[-1].any()  # at rest at both ends


def test_an_older_session_without_them_exports_finite_differences(tmp_path: Path) -> None:
    """A session saved before the motion stored velocities: central differences inside, one-sided at the ends, and no
    accelerations (an empty list per point, no CSV columns)."""
    session = copy_example(tmp_path / "s")
    with np.load(session / "motion.npz") as z:
        arrays = {k: z[k] for k in z.files if k not in ("qd", "qdd")}
    np.savez(session / "motion.npz", **arrays)
    for name in ("t.json", "t.csv"):
        run = export(tmp_path, str(session), "--trajectory", name)
        assert run.returncode == 0, run.stderr
    points = json.loads((tmp_path / "t.json").read_text())["points"]
    v = np.array([p["velocities"] for p in points])
    q, t = arrays["q"], arrays["t"]
    for i in (1, len(t) // 3, 2 * len(t) // 3, len(t) - 2):
        assert np.allclose(v[i], (q[i + 1] - q[i - 1]) / (t[i + 1] - t[i - 1]), atol=1e-9)
    assert np.allclose(v[0], (q[1] - q[0]) / (t[1] - t[0]), atol=1e-9)
    assert np.allclose(v[-1], (q[-1] - q[-2]) / (t[-1] - t[-2]), atol=1e-9)
    assert all(p["accelerations"] == [] for p in points)
    header = next(csv.reader((tmp_path / "t.csv").open()))
    assert not any(h.startswith("acceleration:") for h in header)


def test_csv_has_a_header_and_the_samples_of_motion_npz(written: Path, model_joints: list[str], npz: dict) -> None:
    rows = list(csv.reader((written / "t.csv").open()))
    header, body = rows[0], rows[1:]
    assert header[:3] == ["time", "phase", "holder"]
    positions = [i for i, h in enumerate(header) if h.startswith("position:")]
    velocities = [i for i, h in enumerate(header) if h.startswith("velocity:")]
    accelerations = [i for i, h in enumerate(header) if h.startswith("acceleration:")]
    assert [header[i].removeprefix("position:") for i in positions] == model_joints
    assert [header[i].removeprefix("velocity:") for i in velocities] == model_joints
    assert [header[i].removeprefix("acceleration:") for i in accelerations] == model_joints
    assert len(body) == len(npz["t"])
    assert np.array_equal(np.array([[float(r[i]) for i in positions] for r in body]), npz["q"])
    assert np.array_equal(np.array([[float(r[i]) for i in velocities] for r in body]), npz["qd"])
    assert np.array_equal(np.array([[float(r[i]) for i in accelerations] for r in body]), npz["qdd"])
    assert [float(r[0]) for r in body] == npz["t"].tolist()
    assert [r[1] for r in body] == [PHASES[p] for p in npz["phase"]]


def test_an_existing_file_is_kept_without_force(tmp_path: Path) -> None:
    target = tmp_path / "t.csv"
    target.write_text("mine")
    run = export(tmp_path, str(EXAMPLE), "--trajectory", "t.csv")
    assert run.returncode == 2 and "t.csv" in one_error_line(run.stderr) and "--force" in run.stderr
    assert target.read_text() == "mine"
    assert export(tmp_path, str(EXAMPLE), "--trajectory", "t.csv", "--force").returncode == 0
    assert target.read_text().startswith("time,phase,holder,")


@pytest.mark.parametrize("name", ["t.txt", "t", "t.json.gz"])
def test_a_bad_extension_is_one_line(tmp_path: Path, name: str) -> None:
    run = export(tmp_path, str(EXAMPLE), "--trajectory", name)
    assert run.returncode == 2
    line = one_error_line(run.stderr)
    assert name in line and ".json or .csv" in line
    assert not (tmp_path / name).exists()


def test_stored_joint_names_must_be_the_models(tmp_path: Path) -> None:
    session = copy_example(tmp_path / "s")
    motion = json.loads((session / "motion.json").read_text())
    motion["joint_names"] = ["a", "b"]
    (session / "motion.json").write_text(json.dumps(motion))
    run = export(tmp_path, str(session), "--trajectory", "t.json")
    line = one_error_line(run.stderr)
    assert run.returncode == 2 and "motion.json" in line and "joint_names" in line and "49 joint names" in line


def test_joint_names_are_saved_with_the_motion_and_absent_from_older_files(tmp_path: Path, model_joints: list[str]) -> None:
    """A motion with its names saves and loads them; one without (an older session's) loads without them and saves as it
    was written: no field."""
    example = load_result(Motion, EXAMPLE, "motion")
    assert example.joint_names == tuple(model_joints)
    save_result(dataclasses.replace(example, joint_names=()), tmp_path, "older")
    old = load_result(Motion, tmp_path, "older")
    assert old.joint_names == ()
    save_result(old, tmp_path, "old")
    assert "joint_names" not in json.loads((tmp_path / "old.json").read_text())
    save_result(dataclasses.replace(old, joint_names=tuple(model_joints)), tmp_path, "new")
    assert json.loads((tmp_path / "new.json").read_text())["joint_names"] == model_joints
    assert load_result(Motion, tmp_path, "new").joint_names == tuple(model_joints)


def test_velocities_are_saved_with_the_motion_and_absent_from_older_files(tmp_path: Path) -> None:
    """Optional arrays: a motion saves and loads its velocities and accelerations; one without them (an older session's)
    loads them empty and saves as it was written, without them."""
    example = load_result(Motion, EXAMPLE, "motion")
    assert example.qd.shape == example.qdd.shape == example.q.shape
    save_result(dataclasses.replace(example, qd=np.zeros((0, 0)), qdd=np.zeros((0, 0))), tmp_path, "older")
    with np.load(tmp_path / "older.npz") as z:
        assert "qd" not in z.files and "qdd" not in z.files
    old = load_result(Motion, tmp_path, "older")
    assert old.qd.size == old.qdd.size == 0 and np.array_equal(old.q, example.q)
    save_result(example, tmp_path, "new")
    new = load_result(Motion, tmp_path, "new")
    assert np.array_equal(new.qd, example.qd) and np.array_equal(new.qdd, example.qdd)
