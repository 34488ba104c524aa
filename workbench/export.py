"""Export what is drawn as one self-contained HTML file (viser's scene serializer embeds its client and the scene).

A session with a motion is exported as a recording: the robot and the object posed at one sample per
frame, with the time to the next frame recorded as a pause (`StateSerializer.insert_sleep`), so the
page plays the whole motion offline.
"""
from __future__ import annotations

import contextlib
import io
import itertools
from pathlib import Path

import numpy as np
import viser

from planner.core.results import atomic_write_text
from planner.core.session import Session

from .layers.motion import MotionLayer
from .robot_layer import RobotLayer
from .scene_layer import SceneLayer
from .session_layers import SessionLayers
from .view import setup_view

EXPORT_FPS = 10.0  # recorded frames a second at most ...
MAX_FRAMES = 300  # ... and in all (a longer motion gets fewer frames a second): keeps the file small


def scene_html(server: viser.ViserServer) -> str:
    """The server's current scene (no GUI) as a standalone HTML page that plays offline."""
    return server.get_scene_serializer().as_html()


def frame_samples(t: np.ndarray) -> np.ndarray:
    """The samples of a trajectory timed `t` that an export records: evenly spread, at most EXPORT_FPS a second and
    MAX_FRAMES in all, the first and last included."""
    if len(t) == 0:
        return np.zeros(0, dtype=np.int64)
    frames = int(min(MAX_FRAMES, len(t), np.ceil(float(t[-1] - t[0]) * EXPORT_FPS) + 1))
    return np.unique(np.round(np.linspace(0, len(t) - 1, max(frames, 1))).astype(np.int64))


def motion_html(server: viser.ViserServer, robot: RobotLayer, motion: MotionLayer) -> str:
    """The scene as a recording of the motion: the robot and the object at each of `frame_samples`, in real time."""
    r = motion.result
    assert r is not None
    samples = frame_samples(r.t)
    playback = motion.playback
    assert r is not None and playback is not None
    robot.update(r.q[samples[0]])
    playback.show(int(samples[0]))
    serializer = server.get_scene_serializer()
    for prev, i in itertools.pairwise(samples):
        serializer.insert_sleep(float(r.t[i] - r.t[prev]))
        robot.update(r.q[i])
        playback.show(int(i))
    return serializer.as_html()


def session_html(session_dir: Path) -> str:
    """A saved session drawn (scene, robot at its initial configuration, every step layer) as one HTML page; with a
    motion, the page plays it (the other step layers hidden, the scene's object replaced by the moving one)."""
    session = Session.open(session_dir)
    with contextlib.redirect_stdout(io.StringIO()):  # viser prints its URL banner: nobody will connect to this server
        server = viser.ViserServer("127.0.0.1", 0, label="regrasp export", verbose=False)
        try:
            setup_view(server)
            scene = SceneLayer(server, session.scene)
            robot = RobotLayer(server, session.scene.robot, session.scene.q_initial)
            layers = SessionLayers(server, session)
            motion = layers.layers.get("motion")
            if isinstance(motion, MotionLayer) and motion.result is not None and len(motion.result.t):
                scene.object.visible = False
                for name, layer in layers.layers.items():
                    layer.visible = name == "motion"
                return motion_html(server, robot, motion)
            return scene_html(server)
        finally:
            server.stop()


def export_html(session_dir: Path, out: Path) -> None:
    """Write `session_html` of a saved session to `out`."""
    atomic_write_text(Path(out), session_html(session_dir))
