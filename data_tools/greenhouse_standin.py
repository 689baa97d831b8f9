"""Offline stand-ins for the greenhouse dataset, in the layouts the cleaning tools accept.

* :func:`write_processed_standin` - generated rows (tpvp.synthetic.greenhouse) as the dataset's
  processed models ``Processed_3D_Model/room<k>_<YYYYMMDD>.pcd`` (cropped, aligned, metres).
* :func:`write_raw_standin` - the same rows as raw per-session captures ``raw/room<k>_<YYYYMMDD>_raw.ply``:
  plants plus the static greenhouse (floor, heating-pipe rails in both aisles, posts at the row
  ends, a substrate gutter inside the plant box), a little noise and scattered outliers, each
  session moved by its own known rigid offset (as a handheld capture starts in its own frame), with
  ``landmarks/room<k>_<YYYYMMDD>.csv`` of six picked static points (with 2 mm picking noise) that
  undo the offset. Session 0 is the reference day and keeps the room frame.

The true offsets are returned so tests can check the recovered alignment.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from data_tools.alignment import LANDMARK_COLUMNS, transform_points
from tpvp.io import atomic_write_text, write_point_cloud
from tpvp.scene.boxes import OrientedBox, room_config
from tpvp.synthetic.greenhouse import DATES, generate_row_sessions, save_row_sessions


@dataclass(frozen=True)
class RawStandin:
    folder: Path
    scans: dict  # date -> scan path
    landmarks: dict  # date -> landmarks path (None for the reference day)
    offsets: dict  # date -> (4, 4) reference -> scan frame (the transform alignment must undo)
    plant_points: int  # plant points per session (before noise), for retention checks


def write_processed_standin(folder, room: str = "room1", seed: int = 0, n_sessions: int = 5,
                           point_spacing: float = 0.01) -> Path:
    """Generated sessions as processed models in ``folder/Processed_3D_Model``; returns that folder."""
    sessions = generate_row_sessions(room, seed, n_sessions, point_spacing)
    out = Path(folder) / "Processed_3D_Model"
    save_row_sessions(sessions, out)
    return out


def _grid(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    uu, vv = np.meshgrid(u, v, indexing="ij")
    return np.stack([uu.ravel(), vv.ravel()], axis=1)


def static_structure(box: OrientedBox, spacing: float = 0.02) -> tuple[np.ndarray, np.ndarray]:
    """(points, landmarks) of a static greenhouse around ``box``, world frame: points outside the
    box (floor, pipe rails, posts) plus a flat gutter inside its bottom; landmarks = 6 post/rail
    corners that a user would pick."""
    half = box.half_extent
    floor_z = -half[2] - 0.05
    length = half[0] + 0.6
    aisle = half[1] + 0.9
    parts = []
    uv = _grid(np.arange(-length, length, spacing), np.arange(-aisle, aisle, spacing))
    parts.append(np.column_stack([uv, np.full(len(uv), floor_z)]))  # floor
    angle = np.arange(0, 2 * np.pi, spacing / 0.03)
    for side in (-1.0, 1.0):  # two heating-pipe rails along the row, in the aisles
        along = np.arange(-length, length, spacing)
        a, t = np.meshgrid(along, angle, indexing="ij")
        y = side * (half[1] + 0.3) + 0.03 * np.cos(t)
        z = floor_z + 0.12 + 0.03 * np.sin(t)
        parts.append(np.stack([a.ravel(), y.ravel(), z.ravel()], axis=1))
    for end in (-1.0, 1.0):  # posts beyond the row ends
        height = np.arange(floor_z, half[2] + 0.3, spacing)
        h, t = np.meshgrid(height, np.arange(0, 2 * np.pi, spacing / 0.05), indexing="ij")
        parts.append(np.stack([end * (half[0] + 0.3) + 0.05 * np.cos(t).ravel(),
                               0.05 * np.sin(t).ravel(), h.ravel()], axis=1))
    gutter = _grid(np.arange(-half[0] + 0.1, half[0] - 0.1, spacing / 2), np.arange(-0.12, 0.12, spacing / 2))
    parts.append(np.column_stack([gutter, np.full(len(gutter), -half[2] + 0.02)]))
    local_landmarks = np.array([
        [-(half[0] + 0.3), 0.05, half[2] + 0.3], [half[0] + 0.3, 0.05, half[2] + 0.3],
        [-(half[0] + 0.3), -0.05, floor_z + 0.5], [half[0] + 0.3, -0.05, floor_z + 0.5],
        [-length + 0.1, half[1] + 0.3, floor_z + 0.15], [length - 0.1, -(half[1] + 0.3), floor_z + 0.15],
    ])
    return box.to_world(np.concatenate(parts)), box.to_world(local_landmarks)


def session_offset(k: int, seed: int = 0) -> np.ndarray:
    """Rigid transform (4, 4) from the reference frame to session ``k``'s capture frame: a few
    degrees of yaw, under a degree of tilt, up to half a metre of shift (identity for k = 0)."""
    if k == 0:
        return np.eye(4)
    rng = np.random.default_rng([seed, k, 11])
    yaw, tilt_x, tilt_y = np.radians(rng.uniform(-8, 8)), *np.radians(rng.uniform(-1, 1, 2))
    cz, sz, cx, sx, cy, sy = np.cos(yaw), np.sin(yaw), np.cos(tilt_x), np.sin(tilt_x), np.cos(tilt_y), np.sin(tilt_y)
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    transform = np.eye(4)
    transform[:3, :3] = rz @ rx @ ry
    transform[:3, 3] = rng.uniform(-0.5, 0.5, 3)
    return transform


def write_raw_standin(folder, room: str = "room1", seed: int = 0, n_sessions: int = 3,
                      point_spacing: float = 0.01, noise: float = 0.002,
                      outlier_share: float = 0.005, units: str = "m") -> RawStandin:
    """Write raw captures (``.ply``) and landmark files of ``n_sessions`` generated sessions."""
    folder = Path(folder)
    box = room_config(room).plant_box
    static, landmarks_world = static_structure(box)
    sessions = generate_row_sessions(room, seed, n_sessions, point_spacing)
    scans, landmark_files, offsets = {}, {}, {}
    for k, session in enumerate(sessions):
        rng = np.random.default_rng([seed, k, 5])
        scene = np.concatenate([session.points, static])
        scene = scene + rng.normal(0.0, noise, scene.shape)
        lo, hi = scene.min(axis=0) - 0.3, scene.max(axis=0) + 0.3
        outliers = rng.uniform(lo, hi, (int(outlier_share * len(scene)), 3))
        offset = session_offset(k, seed)
        captured = transform_points(np.concatenate([scene, outliers]), offset)
        name = f"{room}_{DATES[k]}"
        scans[DATES[k]] = write_point_cloud(folder / "raw" / f"{name}_raw.ply",
                                            captured * (1000.0 if units == "mm" else 1.0), dtype="float32")
        offsets[DATES[k]] = offset
        landmark_files[DATES[k]] = None
        if k > 0:
            picked = transform_points(landmarks_world, offset) + rng.normal(0.0, 0.002, landmarks_world.shape)
            table = np.column_stack([picked, landmarks_world])
            text = ",".join(LANDMARK_COLUMNS) + "\n" + "\n".join(",".join(f"{v:.6f}" for v in row) for row in table)
            landmark_files[DATES[k]] = atomic_write_text(folder / "landmarks" / f"{name}.csv", text + "\n")
    return RawStandin(folder=folder, scans=scans, landmarks=landmark_files, offsets=offsets,
                      plant_points=int(np.mean([s.n_points for s in sessions])))
