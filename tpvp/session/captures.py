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


def read_intrinsics(path) -> tuple[Intrinsics, float | None]:
    """``(intrinsics, depth_scale)`` from a YAML or JSON file with ``fx, fy, cx, cy, width,
    height`` (pixels) and optionally ``depth_scale`` (metres per depth unit; None when absent:
    :func:`read_depth`'s default for the file type). Without a file: the simulated D435."""
    import yaml

    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text())
    except OSError as exc:
        raise InputFileError(f"{path}: cannot read the intrinsics file ({exc.strerror or exc})") from None
    except yaml.YAMLError as exc:
        raise InputFileError(f"{path}: not a YAML/JSON intrinsics file ({str(exc).splitlines()[0]})") from None
    if not isinstance(data, dict):
        raise InputFileError(f"{path}: the intrinsics file must map fx, fy, cx, cy, width, height to numbers")
    missing = [key for key in ("fx", "fy", "cx", "cy", "width", "height") if key not in data]
    if missing:
        raise InputFileError(f"{path}: the intrinsics file lacks {', '.join(missing)} (needs fx, fy, cx, cy, "
                             f"width, height in pixels; depth_scale optional)")
    keys = ["fx", "fy", "cx", "cy", "width", "height"] + (["depth_scale"] if data.get("depth_scale") is not None else [])
    try:
        values = {key: float(data[key]) for key in keys}
    except (TypeError, ValueError):
        raise InputFileError(f"{path}: fx, fy, cx, cy, width, height and depth_scale must be numbers") from None
    infinite = [key for key in keys if not np.isfinite(values[key])]
    if infinite:
        raise InputFileError(f"{path}: {', '.join(f'{k} = {data[k]}' for k in infinite)}: the intrinsics must be "
                             f"finite numbers (pixels; depth_scale in metres per unit)")
    if any(values[key] != int(values[key]) for key in ("width", "height")):
        raise InputFileError(f"{path}: width and height must be whole numbers of pixels")
    intrinsics = Intrinsics(values["fx"], values["fy"], values["cx"], values["cy"], int(values["width"]),
                            int(values["height"]))
    depth_scale = values.get("depth_scale")
    if min(intrinsics.fx, intrinsics.fy, intrinsics.width, intrinsics.height, depth_scale or 1) <= 0:
        raise InputFileError(f"{path}: fx, fy, width, height and depth_scale must be positive")
    return intrinsics, depth_scale


def read_depth(path, depth_scale: float | None = None) -> np.ndarray:
    """A depth image in metres (NaN where there is no depth): a ``.npy`` array or a 16-bit
    ``.png``, times ``depth_scale`` (metres per unit; default 1 for ``.npy``, i.e. metres, and
    0.001 for ``.png``, i.e. millimetres as a RealSense writes them). 0 means no measurement."""
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f"{path}: file not found")
    suffix = path.suffix.lower()
    if suffix not in (".npy", ".png"):
        raise InputFileError(f"{path}: a depth image must be a .npy array or a 16-bit .png")
    try:
        if suffix == ".npy":
            raw = np.load(path, allow_pickle=False)
        else:
            from PIL import Image  # matplotlib's dependency, needed only for PNG depth

            with Image.open(path) as image:
                raw = np.asarray(image)
    except (OSError, ValueError) as exc:
        raise InputFileError(f"{path}: cannot read the depth image ({exc})") from None
    if raw.ndim != 2 or not np.issubdtype(raw.dtype, np.number):
        raise InputFileError(f"{path}: a depth image must be one channel of numbers, got shape {raw.shape} "
                             f"({raw.dtype})")
    if np.iscomplexobj(raw):
        raise InputFileError(f"{path}: the depth image holds complex numbers ({raw.dtype}); depth must be real "
                             f"numbers (metres in a .npy)")
    if suffix == ".png" and raw.dtype.itemsize < 2:
        raise InputFileError(f"{path}: an 8-bit PNG cannot hold depth (256 levels); depth must be a 16-bit PNG in "
                             f"millimetres, or a .npy in metres")
    scale = (1.0 if suffix == ".npy" else 0.001) if depth_scale is None else float(depth_scale)
    depth = raw.astype(np.float64) * scale
    depth[~np.isfinite(depth) | (depth <= 0)] = np.nan
    return depth


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
