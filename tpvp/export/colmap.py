"""A session's captures (or a plan's views) as a COLMAP text model with known poses:
``cameras.txt``, ``images.txt`` and ``points3D.txt``, from camera-to-world poses (world frame,
metres, OpenCV camera axes: x right, y down, z forward), one pinhole camera and the model's points.

COLMAP wants world-to-camera poses (``R = R_wc^T``, ``t = -R^T C``) as quaternion w x y z and
translation, in OpenCV camera axes. It puts the centre of the top-left pixel at (0.5, 0.5), OpenCV
(and tpvp's intrinsics, its ray casters and depth back-projection) at (0, 0): its principal point
is tpvp's plus half a pixel (:data:`tpvp.sensor.camera.PIXEL_CENTRE`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tpvp.export.images import GREY, copy_images, frame_names
from tpvp.io import atomic_write_text
from tpvp.sensor.camera import PIXEL_CENTRE, Intrinsics, rotation_to_quaternion


def _numbers(values) -> str:
    return " ".join(format(float(v), ".17g") for v in values)  # 17 digits: a float64 read back exactly


def colmap_cameras(intrinsics: Intrinsics) -> str:
    """``cameras.txt``: camera 1, PINHOLE ``fx fy cx cy`` (COLMAP's pixel centres)."""
    params = (intrinsics.fx, intrinsics.fy, intrinsics.cx + PIXEL_CENTRE, intrinsics.cy + PIXEL_CENTRE)
    return ("# Camera list with one line of data per camera:\n#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
            f"# Number of cameras: 1\n1 PINHOLE {intrinsics.width} {intrinsics.height} {_numbers(params)}\n")


def colmap_images(camera_to_world, names) -> str:
    """``images.txt``: per pose its world-to-camera rotation (quaternion w x y z) and translation,
    camera 1, its image name, and an empty line of 2D points."""
    lines = ["# Image list with two lines of data per image:",
             "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME",
             "#   POINTS2D[] as (X, Y, POINT3D_ID)",
             f"# Number of images: {len(names)}, mean observations per image: 0"]
    for image_id, (pose, name) in enumerate(zip(np.asarray(camera_to_world, dtype=np.float64), names), start=1):
        rotation = pose[:3, :3].T
        x, y, z, w = rotation_to_quaternion(rotation)
        lines += [f"{image_id} {_numbers([w, x, y, z])} {_numbers(-rotation @ pose[:3, 3])} 1 {name}", ""]
    return "\n".join(lines) + "\n"


def colmap_points(points) -> str:
    """``points3D.txt``: each point grey, error 0, no track (no image feature is matched to it)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    lines = ["# 3D point list with one line of data per point:",
             "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)",
             f"# Number of points: {len(points)}, mean track length: 0"]
    lines += [f"{i} {_numbers(p)} {GREY} {GREY} {GREY} 0" for i, p in enumerate(points, start=1)]
    return "\n".join(lines) + "\n"


def write_colmap(folder, camera_to_world, intrinsics: Intrinsics, points, images=None) -> list[str]:
    """Write ``cameras.txt``, ``images.txt`` and ``points3D.txt`` into ``folder`` (and copy
    ``images`` into ``folder/images``); returns the image names ``images.txt`` holds."""
    names = copy_images(images, folder) if images is not None else frame_names(len(camera_to_world))
    folder = Path(folder)
    atomic_write_text(folder / "cameras.txt", colmap_cameras(intrinsics))
    atomic_write_text(folder / "images.txt", colmap_images(camera_to_world, names))
    atomic_write_text(folder / "points3D.txt", colmap_points(points))
    return names
