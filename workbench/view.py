"""The view every workbench scene shares (plain lights, a floor grid, a front-right camera) and animated camera moves."""
from __future__ import annotations

import threading
import time

import numpy as np
import viser

CAMERA_POSITION = (2.1, -1.8, 1.8)  # front-right of the robot, above the desk
CAMERA_LOOK_AT = (0.4, -0.05, 0.85)
CLOSE_UP = 0.9  # m from a framed point, along the overview's line of sight
MOVE_SECONDS = 0.6
MOVE_FRAMES = 18


def setup_view(server: viser.ViserServer) -> None:
    """Hemisphere + sun lights (no HDRI: it can stall headless browsers and needs the network), grid, camera."""
    scene = server.scene
    scene.configure_environment_map(None)
    scene.configure_default_lights(False)
    scene.add_light_hemisphere("/lights/sky", sky_color=(255, 255, 255), ground_color=(120, 110, 100), intensity=1.6)
    scene.add_light_directional("/lights/sun", intensity=1.8, position=(2.0, -1.5, 4.0))
    scene.add_grid("/floor", width=4.0, height=4.0, cell_size=0.25, section_size=1.0)
    server.initial_camera.position = CAMERA_POSITION
    server.initial_camera.look_at = CAMERA_LOOK_AT
    server.initial_camera.up = (0.0, 0.0, 1.0)


def close_up(point: np.ndarray, distance: float = CLOSE_UP) -> tuple[np.ndarray, np.ndarray]:
    """Camera position and target framing `point` from `distance`, seen from the overview's side."""
    direction = np.subtract(CAMERA_POSITION, CAMERA_LOOK_AT)
    point = np.asarray(point, float)
    return point + distance * direction / np.linalg.norm(direction), point


def _glide(client: viser.ClientHandle, position: np.ndarray, look_at: np.ndarray, seconds: float) -> None:
    """Move one client's camera to `position`, looking at `look_at`, eased over `seconds`."""
    camera = client.camera
    p0, t0 = np.asarray(camera.position, float), np.asarray(camera.look_at, float)
    for k in range(1, MOVE_FRAMES + 1):
        s = k / MOVE_FRAMES
        s = s * s * (3 - 2 * s)  # smoothstep: starts and stops gently
        with client.atomic():  # position first: viser's position setter shifts look_at along, which is then set
            camera.up_direction = (0.0, 0.0, 1.0)
            camera.position = tuple(p0 + s * (position - p0))
            camera.look_at = tuple(t0 + s * (look_at - t0))
        time.sleep(seconds / MOVE_FRAMES)


def move_cameras(server: viser.ViserServer, position: np.ndarray, look_at: np.ndarray,
                 seconds: float = MOVE_SECONDS) -> list[threading.Thread]:
    """Glide every connected client's camera to `position` / `look_at` in the background; returns the threads."""
    jobs = [threading.Thread(target=_glide, args=(client, np.asarray(position, float), np.asarray(look_at, float), seconds),
                             daemon=True) for client in server.get_clients().values()]
    for job in jobs:
        job.start()
    return jobs


def follow_cameras(server: viser.ViserServer, shift: np.ndarray) -> None:
    """Move every connected client's camera, and the point it looks at, by `shift` (the camera follows something)."""
    shift = np.asarray(shift, float)
    for client in server.get_clients().values():
        camera = client.camera
        look_at = np.asarray(camera.look_at, float) + shift
        with client.atomic():  # position first: viser's position setter shifts look_at along, which is then set
            camera.position = tuple(np.asarray(camera.position, float) + shift)
            camera.look_at = tuple(look_at)
