"""What a robot's camera hands a session: a cloud in the world frame, or a depth image with its
intrinsics, and the pose it was captured from.

The world frame is the previous session's model's own frame (metres, as read with ``--units``).
A depth image is back-projected with the pinhole intrinsics (OpenCV camera frame: +z along the
optical axis, +x right, +y down; depth is the camera-z distance, the RealSense convention); a
surface point on a voxel's face is given the voxel its ray entered (:func:`surface_voxel_keys`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tpvp.errors import InputFileError
from tpvp.sensor.camera import Intrinsics

#: A depth point this close to a voxel face (in voxels) lies on it: see :func:`surface_voxel_keys`.
FACE_TOLERANCE = 1e-6


def back_project(depth: np.ndarray, intrinsics: Intrinsics, position, rotation,
                 name: str = "depth image") -> tuple[np.ndarray, np.ndarray]:
    """``(points, rays)`` of a depth image (metres, camera-z depth) seen from ``position`` with the
    camera-to-world ``rotation`` (columns: the camera axes): the surface points in the world frame
    and the direction of each one's pixel ray (camera z = 1)."""
    if depth.shape != (intrinsics.height, intrinsics.width):
        raise InputFileError(f"{name}: the image is {depth.shape[1]} x {depth.shape[0]} pixels but the intrinsics "
                             f"say {intrinsics.width} x {intrinsics.height}; give the intrinsics of this "
                             f"image (--intrinsics)")
    v, u = np.nonzero(np.isfinite(depth))
    z = depth[v, u]
    # The same float operations as the pixel kernel's rays: (u - cx) / fx, then the rotation.
    xn = (u.astype(np.float64) - intrinsics.cx) / intrinsics.fx
    yn = (v.astype(np.float64) - intrinsics.cy) / intrinsics.fy
    rot = np.asarray(rotation, dtype=np.float64)
    rays = np.stack([rot[i, 0] * xn + rot[i, 1] * yn + rot[i, 2] for i in range(3)], axis=1)
    return np.asarray(position, dtype=np.float64) + rays * z[:, None], rays


def surface_voxel_keys(points: np.ndarray, rays: np.ndarray, resolution: float) -> np.ndarray:
    """The voxel each surface point of a depth image lies in. A first-surface depth puts the point
    on the face through which its ray entered the voxel: on that face's axis (the one whose
    coordinate is nearest a voxel plane, within ``FACE_TOLERANCE`` voxels) the point belongs to the
    voxel beyond the face along the ray (the one hit), not the empty one before it; on the other
    axes to the voxel it lies in."""
    scaled = np.asarray(points, dtype=np.float64) / resolution
    keys = np.floor(scaled)
    nearest = np.round(scaled)
    gap = np.abs(scaled - nearest)
    axis = np.argmin(gap, axis=1)
    rows = np.flatnonzero(gap[np.arange(len(gap)), axis] < FACE_TOLERANCE)
    entry = axis[rows]
    keys[rows, entry] = nearest[rows, entry] - (rays[rows, entry] < 0)
    return keys.astype(np.int64)


@dataclass(frozen=True)
class Pose:
    """A camera pose in the world frame: position and look-at point."""

    position: np.ndarray
    look_at: np.ndarray


def read_pose_file(path) -> Pose:
    """A pose from a JSON file ``{"position": [x, y, z], "look_at": [x, y, z]}`` or the first row
    of a CSV with ``x,y,z`` and ``look_x,look_y,look_z`` (``plan.csv``'s columns) or
    ``look_at_x,look_at_y,look_at_z``; world frame, metres."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise InputFileError(f"{path}: cannot read the pose file ({exc.strerror or exc})") from None
    try:
        if path.suffix.lower() == ".json":
            data = json.loads(text)
            position, look_at = data["position"], data["look_at"]
        else:
            import pandas as pd
            from io import StringIO

            row = pd.read_csv(StringIO(text), comment="#").iloc[0]
            position = [row["x"], row["y"], row["z"]]
            prefix = "look_" if "look_x" in row.index else "look_at_"
            look_at = [row[f"{prefix}x"], row[f"{prefix}y"], row[f"{prefix}z"]]
        pose = Pose(np.asarray(position, dtype=np.float64).reshape(3), np.asarray(look_at, dtype=np.float64).reshape(3))
    except (KeyError, IndexError, ValueError, TypeError, json.JSONDecodeError):
        raise InputFileError(f"{path}: a pose file is JSON {{\"position\": [x, y, z], \"look_at\": [x, y, z]}} or a "
                             f"CSV whose first row has x,y,z and look_x,look_y,look_z (world frame, metres)") from None
    if not (np.all(np.isfinite(pose.position)) and np.all(np.isfinite(pose.look_at))):
        raise InputFileError(f"{path}: the pose has NaN or infinite coordinates")
    if np.allclose(pose.position, pose.look_at):
        raise InputFileError(f"{path}: the pose looks at its own position")
    return pose
