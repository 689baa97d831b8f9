"""A plan's views as poses in a robot's frame: the rigid base-from-scan transform read from its
file and applied to a plan read back from ``plan.csv`` (:func:`tpvp.io.plan.read_plan`), and the
views as camera-to-world matrices.

The plan's quaternion turns camera axes (OpenCV: x right, y down, z forward) into the plan's frame;
moved into the robot's base frame it turns them into the base frame. Which link carries the
camera, and its offset, is the robot's business: the exports hold the camera's poses.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import yaml

from tpvp.errors import InputFileError
from tpvp.sensor.camera import rigid_error, rotation_to_quaternion

if TYPE_CHECKING:
    import pandas as pd

#: How far a transform's rotation may be from a proper rotation (orthonormal, determinant +1).
RIGID_TOLERANCE = 1e-6


def read_transform(path) -> np.ndarray:
    """A rigid 4x4 transform from a JSON or YAML file: the matrix itself (4 rows of 4), or a
    mapping with it under ``matrix``; one clear error naming the file when it is not rigid."""
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text())  # JSON is YAML
    except OSError as exc:
        raise InputFileError(f"{path}: cannot read the transform ({exc.strerror or exc})") from None
    except yaml.YAMLError as exc:
        raise InputFileError(f"{path}: not JSON or YAML ({str(exc).splitlines()[0]})") from None
    if isinstance(data, dict):
        data = data.get("matrix")
    try:
        matrix = np.asarray(data, dtype=np.float64)
    except (TypeError, ValueError):
        matrix = np.zeros(0)
    if matrix.shape != (4, 4) or not np.isfinite(matrix).all():
        raise InputFileError(f"{path}: a transform is a 4x4 matrix of numbers (or a mapping with it under "
                             f"'matrix'), got {json.dumps(data)[:80]}")
    error = rigid_error(matrix)
    if error > RIGID_TOLERANCE:
        raise InputFileError(f"{path}: not a rigid transform (its rotation is off a proper rotation by {error:.3g}, "
                             f"or its last row is not 0 0 0 1): a scaled or sheared matrix would move the views "
                             f"off their plant; give the base-from-scan pose in metres")
    return matrix


def quaternion_to_rotation(q) -> np.ndarray:
    """The rotation matrix of a unit quaternion (x, y, z, w)."""
    x, y, z, w = np.asarray(q, dtype=np.float64) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def moved_plan(table: pd.DataFrame, matrix: np.ndarray) -> pd.DataFrame:
    """The plan's views moved by the rigid ``matrix`` (positions, look-ats and orientations)."""
    rotation, translation = matrix[:3, :3], matrix[:3, 3]
    moved = table.copy()
    for columns in (["x", "y", "z"], ["look_x", "look_y", "look_z"]):
        moved[columns] = table[columns].to_numpy(dtype=np.float64) @ rotation.T + translation
    quaternions = [rotation_to_quaternion(rotation @ quaternion_to_rotation(q))
                   for q in table[["qx", "qy", "qz", "qw"]].to_numpy(dtype=np.float64)]
    moved[["qx", "qy", "qz", "qw"]] = np.asarray(quaternions).reshape(-1, 4)
    return moved


def plan_poses(table: pd.DataFrame) -> np.ndarray:
    """The plan's camera-to-world poses in execution order, ``(V, 4, 4)`` (OpenCV camera axes)."""
    poses = np.tile(np.eye(4), (len(table), 1, 1))
    poses[:, :3, 3] = table[["x", "y", "z"]].to_numpy(dtype=np.float64)
    poses[:, :3, :3] = [quaternion_to_rotation(q) for q in table[["qx", "qy", "qz", "qw"]].to_numpy(dtype=np.float64)]
    return poses
