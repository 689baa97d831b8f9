"""A stand-in for the robot's camera: today's full scan rendered at the poses a session asks for.

For tutorials and tests: it plays the robot of a real session on a simulated pair. The captures are
what the simulator observes (:mod:`tpvp.scene.simulator`, ``scene.frame = previous`` at native
scale, the frame a real session plans in), handed over as a real camera would: a cloud in the
world frame (the observed voxel centres), or a depth image in metres (the pixel model's
first-surface depth at the camera's intrinsics).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from tpvp.scene.simulator import build_scene, observation
from tpvp.sensor.sensor import depth_image
from tpvp.session.plant import session_config


class StandInCamera:
    """Renders captures of ``current`` (today's full scan, the previous model's frame) for a
    session planning on ``previous`` under ``config``."""

    def __init__(self, previous, current, config, names=("previous model", "today's scan")):
        self.config = session_config(config)
        self.scene = build_scene(previous, current, self.config, names)

    def _to_world(self, points) -> np.ndarray:
        matrix = self.scene.plant_from_scan
        return (np.asarray(points, dtype=np.float64) - matrix[:3, 3]) @ np.linalg.inv(matrix[:3, :3]).T

    def cloud(self, view: int) -> np.ndarray:
        """What ``view`` observes of today's plant: voxel centres in the world frame."""
        return self._to_world(observation(self.scene, view))

    def depth(self, view: int) -> np.ndarray:
        """The depth image (metres, NaN where nothing is seen) of ``view`` at the sensor's
        intrinsics, every pixel."""
        space = self.scene.view_space
        sensor = replace(self.scene.sensor, model="pixel", pixel_stride=1)
        depth, _ = depth_image(self.scene.grid, space.positions[view], space.look_ats[view], sensor)
        depth = depth / self.scene.scan_scale
        depth[~np.isfinite(depth)] = np.nan
        return depth
