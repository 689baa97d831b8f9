"""Camera poses handed to reconstruction tools: a nerfstudio ``transforms.json`` and a COLMAP text
model, from camera-to-world poses (world frame, metres, OpenCV camera axes: x right, y down,
z forward), one pinhole camera and the model's points.

The conventions each tool expects, and where they differ from tpvp's:

- **nerfstudio** wants camera-to-world matrices with OpenGL camera axes (x right, y up, z
  backward): :func:`tpvp.sensor.camera.switch_camera_axes` negates the y and z columns.
- **COLMAP** wants world-to-camera poses (``R = R_wc^T``, ``t = -R^T C``) as quaternion w x y z
  and translation, in OpenCV camera axes.
- **Both** put the centre of the top-left pixel at (0.5, 0.5), OpenCV (and tpvp's intrinsics, its
  ray casters and depth back-projection) at (0, 0): their principal point is tpvp's plus half a
  pixel (:data:`tpvp.sensor.camera.PIXEL_CENTRE`).

The images are named ``frame_00001.png`` ... in capture order (zero-padded, so a sort by name keeps
that order, as nerfstudio sorts its frames).
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np

from tpvp.errors import InputFileError
from tpvp.io import atomic_write_text, write_point_cloud
from tpvp.sensor.camera import PIXEL_CENTRE, Intrinsics, rotation_to_quaternion, switch_camera_axes

#: The colour files an ``--images`` folder is read for (other files there are left alone).
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")
IMAGES = "images"  # the image folder inside an export, as nerfstudio's and COLMAP's examples name it
GREY = 128  # the points' colour: the fused model has none; nerfstudio reads one per point to seed its splats
PLY_NAME = "sparse_pc.ply"  # the name nerfstudio's ns-process-data gives its initial points


def frame_names(count: int, suffixes=None) -> list[str]:
    """``frame_00001.png`` ... (``suffixes``: each image's own extension, default ``.png``)."""
    suffixes = suffixes or [".png"] * count
    return [f"frame_{i + 1:05d}{suffix.lower()}" for i, suffix in enumerate(suffixes)]


def image_files(folder, count: int, what: str = "captures") -> list[Path]:
    """The colour images in ``folder`` (by :data:`IMAGE_SUFFIXES`), sorted by name: the first is the
    first capture's (of ``what``). One clear error when the folder is missing or holds another number
    of them."""
    folder = Path(folder)
    if not folder.is_dir():
        raise InputFileError(f"--images {folder}: no such folder")
    files = sorted(p for p in folder.iterdir()
                   if p.is_file() and not p.name.startswith(".") and p.suffix.lower() in IMAGE_SUFFIXES)
    if len(files) != count:
        raise InputFileError(f"--images {folder}: {len(files)} images ({'/'.join(IMAGE_SUFFIXES)}) for {count} "
                             f"{what}; give one colour image per {what[:-1]}, sorted by name in their order")
    return files


def copy_images(files, folder) -> list[str]:
    """Copy ``files`` into ``folder/images`` as :func:`frame_names`; returns their names there."""
    names = frame_names(len(files), [Path(f).suffix for f in files])
    (Path(folder) / IMAGES).mkdir(parents=True, exist_ok=True)
    for source, name in zip(files, names):
        try:
            shutil.copyfile(source, Path(folder) / IMAGES / name)
        except OSError as exc:
            if str(exc.filename) != str(source):
                raise  # writing the copy failed: the publishing reports it (a full disk, exit status 4)
            raise InputFileError(f"{source}: cannot read the image ({exc.strerror or exc})") from None
    return names


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


def write_nerfstudio(folder, camera_to_world, intrinsics: Intrinsics, points, images=None) -> list[str]:
    """Write ``transforms.json`` and :data:`PLY_NAME` into ``folder`` (and copy ``images``, one
    per pose in order, into ``folder/images``); returns the image names ``transforms.json`` holds."""
    names = copy_images(images, folder) if images is not None else frame_names(len(camera_to_world))
    write_point_cloud(Path(folder) / PLY_NAME, points, colors=np.full((len(points), 3), GREY, dtype=np.uint8))
    transforms = nerfstudio_transforms(camera_to_world, intrinsics, names)
    atomic_write_text(Path(folder) / "transforms.json", json.dumps(transforms, indent=2) + "\n")
    return names


def write_colmap(folder, camera_to_world, intrinsics: Intrinsics, points, images=None) -> list[str]:
    """Write ``cameras.txt``, ``images.txt`` and ``points3D.txt`` into ``folder`` (and copy
    ``images`` into ``folder/images``); returns the image names ``images.txt`` holds."""
    names = copy_images(images, folder) if images is not None else frame_names(len(camera_to_world))
    folder = Path(folder)
    atomic_write_text(folder / "cameras.txt", colmap_cameras(intrinsics))
    atomic_write_text(folder / "images.txt", colmap_images(camera_to_world, names))
    atomic_write_text(folder / "points3D.txt", colmap_points(points))
    return names
