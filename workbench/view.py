"""The view every workbench scene shares: plain lights, a floor grid and a front-right camera."""
from __future__ import annotations

import viser

CAMERA_POSITION = (2.1, -1.8, 1.8)  # front-right of the robot, above the desk
CAMERA_LOOK_AT = (0.4, -0.05, 0.85)


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
