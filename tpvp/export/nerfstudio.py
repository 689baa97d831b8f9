"""A session's captures for nerfstudio: ``transforms.json`` and the initial points
(:data:`PLY_NAME`), from camera-to-world poses (world frame, metres, OpenCV camera axes: x right,
y down, z forward), one pinhole camera and the model's points.

nerfstudio wants camera-to-world matrices with OpenGL camera axes (x right, y up, z backward):
:func:`tpvp.sensor.camera.switch_camera_axes` negates the y and z columns. It puts the centre of
the top-left pixel at (0.5, 0.5), OpenCV (and tpvp's intrinsics, its ray casters and depth
back-projection) at (0, 0): its principal point is tpvp's plus half a pixel
(:data:`tpvp.sensor.camera.PIXEL_CENTRE`).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from tpvp.export.images import GREY, IMAGES, copy_images, frame_names
from tpvp.io import atomic_write_text, write_point_cloud
from tpvp.sensor.camera import PIXEL_CENTRE, Intrinsics, switch_camera_axes

PLY_NAME = "sparse_pc.ply"  # the name nerfstudio's ns-process-data gives its initial points


def nerfstudio_transforms(camera_to_world, intrinsics: Intrinsics, names) -> dict:
    """nerfstudio's ``transforms.json``: one pinhole camera without distortion and one frame per
    pose (OpenGL camera axes), images under ``images/``, initial points in :data:`PLY_NAME`."""
    poses = switch_camera_axes(camera_to_world)
    return {"camera_model": "OPENCV", "fl_x": intrinsics.fx, "fl_y": intrinsics.fy,
            "cx": intrinsics.cx + PIXEL_CENTRE, "cy": intrinsics.cy + PIXEL_CENTRE,
            "w": intrinsics.width, "h": intrinsics.height, "k1": 0.0, "k2": 0.0, "p1": 0.0, "p2": 0.0,
            "frames": [{"file_path": f"{IMAGES}/{name}", "transform_matrix": pose.tolist()}
                       for name, pose in zip(names, poses)],
            "ply_file_path": PLY_NAME}


def write_nerfstudio(folder, camera_to_world, intrinsics: Intrinsics, points, images=None) -> list[str]:
    """Write ``transforms.json`` and :data:`PLY_NAME` into ``folder`` (and copy ``images``, one
    per pose in order, into ``folder/images``); returns the image names ``transforms.json`` holds."""
    names = copy_images(images, folder) if images is not None else frame_names(len(camera_to_world))
    write_point_cloud(Path(folder) / PLY_NAME, points, colors=np.full((len(points), 3), GREY, dtype=np.uint8))
    transforms = nerfstudio_transforms(camera_to_world, intrinsics, names)
    atomic_write_text(Path(folder) / "transforms.json", json.dumps(transforms, indent=2) + "\n")
    return names
