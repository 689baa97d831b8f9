"""A stand-in for the robot's camera: today's full scan rendered at the poses a session asks for.

For tutorials and tests: it plays the robot of a real session on a simulated pair. The captures are
what the simulator observes (:mod:`tpvp.simulate.world`, ``scene.frame = previous`` at native
scale, the frame a real session plans in), handed over as a real camera would: a cloud in the
world frame (the observed voxel centres), or a depth image in metres (the pixel model's
first-surface depth at the camera's intrinsics).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from tpvp.errors import ConfigError
from tpvp.scene.frame import scan_points
from tpvp.sensor.noise import apply_depth_noise, noise_profile
from tpvp.sensor.sensor import depth_image
from tpvp.simulate.depth_captures import rendered_depth
from tpvp.simulate.greenhouse import build_row_scene, noisy_capture, observed_points
from tpvp.simulate.world import build_scene
from tpvp.session.plant import PlantSession
from tpvp.visibility import safe_visibility


class StandInCamera:
    """Renders captures of ``current`` (today's full scan, the previous model's frame) for a
    session planning on ``previous`` under ``config``."""

    def __init__(self, previous, current, config, names=("previous model", "today's scan"), organs=(None, None)):
        self.config = PlantSession.session_config(config)
        self.scene = build_scene(previous, current, self.config, names, organs)

    def cloud(self, view: int) -> np.ndarray:
        """What ``view`` observes of today's plant: voxel centres in the world frame."""
        return scan_points(self.scene.plant_from_scan, self.scene.observe(view))

    def depth(self, view: int, capture: int = 0) -> np.ndarray:
        """The depth image (metres, NaN where nothing is seen) of ``view`` at the sensor's
        intrinsics, every pixel, with the configured sensor's depth errors (``sensor.noise``:
        :func:`tpvp.sensor.noise.apply_depth_noise`, drawn from ``default_rng([seed, view, capture])``
        as :meth:`~tpvp.simulate.world.Scene.observe` draws a cloud's). The pose error is left out: a
        session places an image at the pose it asked for, and the stand-in renders it there."""
        scene = self.scene
        depth = rendered_depth(scene, view)
        profile = noise_profile(self.config.sensor.noise)
        if not profile.ideal:  # the profile's figures are metres of the sensor's world
            rng = np.random.default_rng([int(scene.seed), int(view), int(capture)])
            metres, _ = apply_depth_noise(profile, depth / scene.per_metre, scene.sensor.intrinsics, np.eye(4),
                                          int(capture), len(scene.view_space), rng, drift_seed=int(scene.seed))
            depth = metres * scene.per_metre
        depth = depth / scene.scan_scale
        depth[~(depth > 0)] = np.nan
        return depth


class RowStandInCamera:
    """Renders captures of ``current`` (today's row, the room's frame) at any pose, for a row
    session planning on ``previous`` under ``config`` (the simulator's row scene; its oracle is
    cached in ``cache_dir``)."""

    def __init__(self, previous, current, config, names=("previous row", "today's row"), cache_dir=None):
        self.config = config
        self.scene = build_row_scene(previous, current, config, names, cache_dir=cache_dir)

    def cloud(self, position, look_at, view: int | None = None, capture: int | None = None) -> np.ndarray:
        """What the pose observes of today's row (room frame): per voxel seen, the centroid of the
        row's points in it (``coarse = centroids``) or its centre, as the simulator's passive sweep,
        through the configured sensor (``sensor.noise``) as the simulator's sweep draws it: ``view``
        (by default the passive-sweep view at this exact pose) and ``capture`` (by default ``view``:
        its place in the session's order) seed the noise; the sequence is the sweep's 15 captures
        (longer when ``capture`` is later). A pose off the sweep needs ``view`` under a noisy sensor."""
        scene = self.scene
        seen = safe_visibility(scene.grid, np.reshape(position, (1, 3)), np.reshape(look_at, (1, 3)), scene.sensor)
        points = observed_points(scene.grid, scene.current) if self.config.coarse == "centroids" else scene.grid.centres
        profile = noise_profile(self.config.sensor.noise)
        if profile.ideal:
            return points[seen[0].indices]
        room = scene.room
        if view is None:
            at = np.flatnonzero(np.all(room.initial_positions == np.reshape(position, (1, 3)), axis=1)
                                & np.all(room.initial_look_ats == np.reshape(look_at, (1, 3)), axis=1))
            if not len(at):
                raise ConfigError(f"sensor.noise {self.config.sensor.noise!r}: a pose off the passive sweep needs "
                                  f"its view index (cloud(..., view=N)) to seed its noise")
            view = int(at[0])
        capture = int(view if capture is None else capture)
        return noisy_capture(profile, points[np.sort(seen[0].indices)], np.reshape(position, 3), view, capture,
                             max(len(room.initial_positions), capture + 1), self.config.seed)

    def depth(self, position, look_at) -> np.ndarray:
        """The depth image (metres, NaN where nothing is seen) of the pose, every pixel."""
        sensor = replace(self.scene.sensor, model="pixel", pixel_stride=1)
        depth, _ = depth_image(self.scene.grid, np.asarray(position, dtype=np.float64),
                               np.asarray(look_at, dtype=np.float64), sensor)
        depth[~np.isfinite(depth)] = np.nan
        return depth
