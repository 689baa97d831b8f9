"""Rerun recordings (``.rrd``): clouds, camera frusta and paths, viewable with ``rerun file.rrd``."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tpvp.io.atomic import atomic_write_bytes
from tpvp.sensor.camera import D435, look_at_rotation

#: Points logged per cloud at most: larger clouds (multi-million-point scans at full resolution)
#: are shown as a uniform random subsample (seed 0), and the recording says so under ``notes``.
MAX_DISPLAY_POINTS = 300_000


def display_points(points, limit: int = MAX_DISPLAY_POINTS) -> tuple[np.ndarray, int]:
    """``(points to log as float32 (n, 3), points in the cloud)``: every point up to ``limit``,
    else ``limit`` of them drawn without replacement (deterministic), in their original order."""
    points = np.asarray(points).reshape(-1, 3)
    total = len(points)
    if total > limit:
        keep = np.sort(np.random.default_rng(0).choice(total, limit, replace=False))
        points = points[keep]
    return np.asarray(points, dtype=np.float32), total


def write_recording(path, clouds: dict, cameras: dict | None = None, paths: dict | None = None,
                    application: str = "tpvp", path_colours: dict | None = None) -> Path:
    """Save a rerun recording.

    ``clouds``: name -> (points, rgb colour tuple); ``cameras``: group name -> (positions, look_ats);
    ``paths``: name -> polyline ``(n, 3)`` (purple unless ``path_colours`` names an rgb). Frusta
    use the D435 intrinsics. Clouds of more than
    :data:`MAX_DISPLAY_POINTS` points are logged as a deterministic subsample, noted in the
    recording (entity ``notes/display``).
    """
    import rerun as rr  # imported lazily: the viewer SDK is heavy and only needed here

    path = Path(path)
    recording = rr.RecordingStream(application)
    # Recorded in memory, then written by the atomic writer like every other output: rerun's own
    # file sink waits forever on a full disk instead of raising.
    memory = recording.memory_recording()
    recording.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    notes = []
    for name, (points, colour) in clouds.items():
        points, total = display_points(points)
        if len(points) < total:
            notes.append(f"- `world/{name}`: {len(points):,} of {total:,} points shown "
                         f"(uniform random subsample for display, seed 0)")
        recording.log(f"world/{name}", rr.Points3D(points, colors=colour, radii=0.0008), static=True)
    if notes:
        recording.log("notes/display", rr.TextDocument(
            f"Clouds of more than {MAX_DISPLAY_POINTS:,} points are subsampled for display:\n\n"
            + "\n".join(notes), media_type=rr.MediaType.MARKDOWN), static=True)
    for group, (positions, look_ats) in (cameras or {}).items():
        positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
        look_ats = np.broadcast_to(np.asarray(look_ats, dtype=np.float64).reshape(-1, 3), positions.shape)
        for i, (p, t) in enumerate(zip(positions, look_ats)):
            entity = f"world/{group}/{i:03d}"
            recording.log(entity, rr.Transform3D(translation=p, mat3x3=look_at_rotation(p, t)), static=True)
            recording.log(entity, rr.Pinhole(focal_length=[D435.fx, D435.fy],
                                             principal_point=[D435.cx, D435.cy],
                                             width=D435.width, height=D435.height,
                                             camera_xyz=rr.ViewCoordinates.RDF,
                                             image_plane_distance=0.03), static=True)
    for name, polyline in (paths or {}).items():
        recording.log(f"world/{name}", rr.LineStrips3D([np.asarray(polyline, dtype=np.float32)],
                                                       colors=(path_colours or {}).get(name, (128, 0, 160))),
                      static=True)
    recording.flush()
    data = memory.drain_as_bytes()
    recording.disconnect()
    return atomic_write_bytes(path, data)
