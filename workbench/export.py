"""Export what is drawn as one self-contained HTML file (viser's scene serializer embeds its client and the scene)."""
from __future__ import annotations

import contextlib
import io
from pathlib import Path

import viser

from planner.results import atomic_write_text
from planner.session import Session

from .robot_layer import RobotLayer
from .scene_layer import SceneLayer
from .session_layers import SessionLayers
from .view import setup_view


def scene_html(server: viser.ViserServer) -> str:
    """The server's current scene (no GUI) as a standalone HTML page that plays offline."""
    return server.get_scene_serializer().as_html()


def export_html(session_dir: Path, out: Path) -> None:
    """Draw a saved session (scene, robot at its initial configuration, every step layer) and write it as HTML."""
    session = Session.open(session_dir)
    with contextlib.redirect_stdout(io.StringIO()):  # viser prints its URL banner: nobody will connect to this server
        server = viser.ViserServer("127.0.0.1", 0, label="regrasp export", verbose=False)
        try:
            setup_view(server)
            SceneLayer(server, session.scene)
            RobotLayer(server, session.scene.robot, session.scene.q_initial)
            SessionLayers(server, session)
            html = scene_html(server)
        finally:
            server.stop()
    atomic_write_text(Path(out), html)
