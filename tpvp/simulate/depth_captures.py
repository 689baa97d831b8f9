"""The depth images a simulated session captures, and the model fused from them.

A view's image is today's ground truth rendered by the pixel model at the sensor's intrinsics,
every pixel, then passed through the configured sensor (``sensor.noise``,
:func:`tpvp.sensor.noise.apply_depth_noise`): depth errors, dropouts, mixed pixels and the pose the
tracking reports. Capture ``i`` of ``n`` draws from ``default_rng([seed, view, i])``, as
:meth:`tpvp.simulate.world.Scene.observe` draws a cloud's. The fused model is what
:func:`tpvp.fusion.fuse_frames` makes of them, the code ``tpvp capture fuse`` runs on a phone's
frames: in the scan's frame (metres), what a session exports as the next session's prior.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from tpvp.fusion.tsdf import DepthFrame, fusion_config, fuse_frames
from tpvp.scene.frame import scan_points
from tpvp.sensor.camera import look_at_rotation
from tpvp.sensor.noise import apply_depth_noise, noise_profile
from tpvp.sensor.sensor import depth_image


def sensor_pose(scene, view: int) -> np.ndarray:
    """The camera-to-world pose of ``view`` in the sensor's world (the planning frame in the
    noise profile's metres, :attr:`~tpvp.simulate.world.Scene.per_metre`; 4x4, OpenCV axes)."""
    space = scene.view_space
    pose = np.eye(4)
    pose[:3, :3] = look_at_rotation(space.positions[view], space.look_ats[view])
    pose[:3, 3] = space.positions[view] / scene.per_metre
    return pose


def rendered_depth(scene, view: int) -> np.ndarray:
    """The exact depth image of ``view`` (planning-frame units along the camera's z, 0 where
    nothing is seen), every pixel of the sensor's intrinsics."""
    space = scene.view_space
    sensor = replace(scene.sensor, model="pixel", pixel_stride=1)
    depth, _ = depth_image(scene.grid, space.positions[view], space.look_ats[view], sensor)
    depth[~np.isfinite(depth)] = 0.0
    return depth


def captured_frame(scene, view: int, capture: int = 0, captures: int = 1) -> DepthFrame:
    """Capture ``capture`` of ``captures``, taken at ``view``: its depth image (the sensor's
    metres, 0 for no return) at the pose the sensor reports (:func:`sensor_pose`), as the
    configured sensor gives them."""
    depth, pose = rendered_depth(scene, view) / scene.per_metre, sensor_pose(scene, view)
    profile = noise_profile(getattr(scene.sensor, "noise", "ideal"))
    if not profile.ideal:
        rng = np.random.default_rng([int(scene.seed), int(view), int(capture)])
        depth, pose = apply_depth_noise(profile, depth, scene.sensor.intrinsics, pose, int(capture), int(captures),
                                        rng, drift_seed=int(scene.seed))
    return DepthFrame(np.asarray(depth, dtype=np.float32), scene.sensor.intrinsics, pose, name=f"view {view}")


def fused_captures(scene, views, progress: bool = False) -> np.ndarray:
    """The model fused from the depth images of ``views`` (in capture order), in the scan's frame
    (metres): :func:`tpvp.fusion.fuse_frames` at a single plant's defaults in the sensor's world,
    each frame's pose refined against the model fused so far when the sensor's poses have errors."""
    views = [int(v) for v in views]
    profile = noise_profile(getattr(scene.sensor, "noise", "ideal"))
    frames = [captured_frame(scene, view, i, len(views)) for i, view in enumerate(views)]
    config = fusion_config("plant", refine_poses=bool(profile.jitter_m or profile.jitter_deg or profile.drift_m
                                                        or profile.drift_deg))
    fused = fuse_frames(frames, config, progress=progress, source="the simulated captures").points * scene.per_metre
    if len(scene.table_points):  # the table is captured too, but is not the plant: cut a fusion voxel above it
        fused = fused[fused[:, 2] > scene.table_points[:, 2].max() + config.voxel_size * scene.per_metre]
    return scan_points(scene.plant_from_scan, fused)
