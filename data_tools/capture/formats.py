"""A phone's or depth camera's capture read as frames: depth, colour, confidence, pose, intrinsics.

Three layouts (:data:`FORMATS`), detected from the folder or named:

* ``nerfstudio``: ``transforms.json`` as ``ns-process-data`` writes it (from Polycam, Record3D,
  KIRI ...). ``transform_matrix`` is camera-to-world with **OpenGL camera axes** (x right, y up,
  z backward); ``fl_x, fl_y, cx, cy, w, h`` (top level, or per frame) are the pinhole intrinsics of
  the colour images; every frame needs a ``depth_file_path`` (16-bit PNG in millimetres, or a
  ``.npy`` in metres). The points come out in the frame of ``transform_matrix``.
* ``polycam``: Polycam's raw-data export, ``keyframes/`` with ``images/*.jpg``, ``cameras/*.json``
  (``fx, fy, cx, cy, width, height`` of the image and ``t_00`` .. ``t_23``: the 3x4 camera-to-world
  pose in ARKit's world, y up, OpenGL camera axes), ``depth/*.png`` (16-bit millimetres) and
  ``confidence/*.png`` (ARKit's levels 0 low, 1 medium, 2 high); ``corrected_cameras`` and
  ``corrected_images`` are used when present. The world is turned z-up exactly as ``ns-process-data``
  turns it ((x, y, z) -> (z, x, y)), so both imports of one capture give the same points.
* ``depth``: a plain folder (OpenCV's and Open3D's pixel coordinates, the top-left pixel's centre
  at (0, 0); nerfstudio and Polycam put it at (0.5, 0.5): :data:`~tpvp.sensor.camera.PIXEL_CENTRE`): ``intrinsics.yaml`` (or ``.json``: ``fx, fy, cx, cy, width, height``
  of the depth images, optionally ``depth_scale``), ``depth/NAME.png|.npy``, ``poses/NAME.txt`` (a
  4x4 camera-to-world matrix with **OpenCV camera axes**, x right, y down, z forward, metres) and
  optionally ``color/NAME.png|.jpg`` and ``confidence/NAME.png``, matched by NAME.

A depth image smaller than the colour intrinsics (a phone's 256 x 192 LiDAR depth beside its
1920 x 1440 image) uses them scaled by the size ratio; a depth image of another aspect ratio is
refused. Depth is the distance along the camera's optical axis (0 or NaN: no measurement).

Every frame's name (the stem of its files) follows one rule, :func:`check_frame_name`.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from data_tools.errors import InputFileError
from tpvp.registry import Registry
from tpvp.sensor.camera import PIXEL_CENTRE, Intrinsics, rigid_error, switch_camera_axes
from tpvp.sensor.images import read_depth, read_intrinsics

#: How far a pose may be from a rigid transform (phones write float32 poses).
RIGID_TOLERANCE = 1e-4
#: A frame's name: letters, digits, '.', '-', '_', a letter or digit first (what phones and
#: ns-process-data write): one word in a message or a shell, one file name in every folder.
FRAME_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]*")
FRAME_NAME_RULE = "a frame name is letters, digits, '.', '-' and '_', starting with a letter or digit"
#: The z-up world ``ns-process-data`` makes of ARKit's y-up one: (x, y, z) -> (z, x, y).
ARKIT_TO_Z_UP = np.array([[0, 0, 1, 0], [1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 0, 1]], dtype=np.float64)
#: Confidence images with values above this hold 0-255 rather than ARKit's levels 0, 1, 2.
CONFIDENCE_LEVELS = 2

READERS = Registry("capture format")
FORMATS = ("nerfstudio", "polycam", "depth")  # READERS' names, in the order of the docs


@dataclass(frozen=True)
class Frame:
    """One frame: its files, its camera-to-world pose (OpenCV camera axes, metres) and the pinhole
    intrinsics its depth is read with (those of the colour image when the depth is smaller)."""

    name: str
    depth: Path
    camera_to_world: np.ndarray
    intrinsics: Intrinsics
    depth_scale: float | None = None  # metres per unit; None: 0.001 for .png, 1 for .npy
    image: Path | None = None
    confidence: Path | None = None


@dataclass(frozen=True)
class Capture:
    folder: Path
    format: str
    frames: tuple[Frame, ...]


def check_frame_name(name: str, source) -> str:
    """``name`` when it is a frame name (:data:`FRAME_NAME`); else one line naming ``source`` (the
    file that gives the name), the character at fault and the rule."""
    if FRAME_NAME.fullmatch(name):
        return name
    if not name:
        fault = "is empty"
    elif not name[0].isascii() or not name[0].isalnum():
        fault = f"starts with {name[0]!r}"
    else:
        char = next(c for c in name if not (c.isascii() and (c.isalnum() or c in "._-")))
        fault = {" ": "holds a space", "/": "holds a slash", "\\": "holds a backslash"}.get(char, f"holds {char!r}")
    raise InputFileError(f"{source}: the frame name {name!r} {fault}: {FRAME_NAME_RULE} (no spaces or slashes); "
                         f"rename the frame's files")


def detect_format(folder: Path) -> str:
    """The layout of a capture folder; one line saying what was expected when it is none."""
    if not folder.is_dir():
        raise InputFileError(f"{folder}: no such capture folder")
    if not any(folder.iterdir()):
        raise InputFileError(f"{folder}: the capture folder is empty; copy the phone's export into it")
    if (folder / "transforms.json").is_file():
        return "nerfstudio"
    if (folder / "keyframes" / "cameras").is_dir() or ((folder / "cameras").is_dir() and (folder / "depth").is_dir()):
        return "polycam"
    if (folder / "depth").is_dir() and _intrinsics_file(folder, required=False) is not None:
        return "depth"
    raise InputFileError(f"{folder}: cannot tell the capture's format: expected transforms.json (nerfstudio), "
                         f"keyframes/cameras/ (Polycam raw data) or depth/ + poses/ + intrinsics.yaml (a depth "
                         f"folder); name it with --format {'|'.join(FORMATS)}")


def read_capture(folder, fmt: str | None = None, depth_scale: float | None = None) -> Capture:
    """Every frame of the capture in ``folder`` (layout ``fmt``, detected when None), checked:
    each frame's name follows the rule, its files exist, its depth image's header gives a size
    that fits its intrinsics, and its pose is finite and rigid. ``depth_scale`` (metres per depth
    unit) replaces the layout's. The depth itself is checked by :func:`~data_tools.capture.fusion.frame_depths`."""
    folder = Path(folder)
    if fmt is None:
        fmt = detect_format(folder)
    elif not folder.is_dir():
        raise InputFileError(f"{folder}: no such capture folder")
    frames = READERS.get(fmt)(folder)
    if not frames:
        raise InputFileError(f"{folder}: the {fmt} capture holds no frames")
    if depth_scale is not None:
        if not depth_scale > 0:
            raise InputFileError(f"--depth-scale must be > 0 (metres per depth unit), got {depth_scale!r}")
        frames = [replace(frame, depth_scale=depth_scale) for frame in frames]
    for frame in frames:
        check_frame_name(frame.name, frame.depth)  # the readers check it where it is read: a safety net
        for path in (frame.depth, frame.image, frame.confidence):
            if path is not None and not path.is_file():
                raise InputFileError(f"{path}: missing (frame {frame.name} names it); copy the whole export, or "
                                     f"remove the frame")
        depth_intrinsics(frame, _image_shape(frame.depth))
        if not np.isfinite(frame.camera_to_world).all():  # the readers name the field; a reader's safety net
            raise InputFileError(f"{folder}: frame {frame.name}'s pose holds NaN or infinite numbers: poses must be "
                                 f"finite camera-to-world matrices in metres")
        error = rigid_error(frame.camera_to_world)
        if error > RIGID_TOLERANCE:
            raise InputFileError(f"{folder}: frame {frame.name}'s pose is not a rigid transform (its rotation is off "
                                 f"a proper rotation by {error:.3g}): poses must be camera-to-world rotations and "
                                 f"translations in metres")
    return Capture(folder, fmt, tuple(frames))


def _image_shape(path: Path) -> tuple[int, ...]:
    """(rows, columns) of an image, or a ``.npy`` array's shape, from its header, without reading its pixels."""
    try:
        if path.suffix.lower() == ".npy":
            return np.load(path, mmap_mode="r", allow_pickle=False).shape
        from PIL import Image  # matplotlib's dependency

        with Image.open(path) as image:
            return image.size[::-1]
    except (OSError, ValueError) as exc:
        raise InputFileError(f"{path}: cannot read the depth image ({exc})") from None


def load_depth(frame: Frame) -> tuple[np.ndarray, Intrinsics]:
    """The frame's depth in metres (NaN: none) and the intrinsics of its pixels; one line naming
    the file for a depth image whose size disagrees with the intrinsics."""
    depth = read_depth(frame.depth, frame.depth_scale)
    return depth, depth_intrinsics(frame, depth.shape)


def depth_intrinsics(frame: Frame, shape) -> Intrinsics:
    """The intrinsics of a depth image of ``shape`` (rows, columns): the frame's own, or scaled by
    the size ratio when the depth image is the colour image's at a lower resolution."""
    k = frame.intrinsics
    if len(shape) != 2:
        raise InputFileError(f"{frame.depth}: frame {frame.name}'s depth image has shape {tuple(shape)}: a depth "
                             f"image is one channel of rows x columns; export the frame again, or remove it")
    height, width = shape
    if min(width, height) == 0:  # an interrupted export: no pixel to fuse, and no size ratio to scale by
        raise InputFileError(f"{frame.depth}: frame {frame.name}'s depth image is {width} x {height} pixels "
                             f"(empty); export the frame again, or remove it")
    if (width, height) == (k.width, k.height):
        return k
    sx, sy = width / k.width, height / k.height
    if abs(sx - sy) > 0.01 * max(sx, sy):
        raise InputFileError(f"{frame.depth}: the depth image is {width} x {height} pixels but the intrinsics say "
                             f"{k.width} x {k.height} (another aspect ratio): give the intrinsics of this camera")
    return k.resized(width, height)


def load_confidence(frame: Frame, shape) -> np.ndarray | None:
    """The frame's confidence as ARKit's levels (0 low, 1 medium, 2 high) at ``shape``; None
    without a confidence image."""
    if frame.confidence is None:
        return None
    from PIL import Image  # matplotlib's dependency

    with Image.open(frame.confidence) as image:
        levels = np.asarray(image)
    if levels.ndim != 2 or levels.shape != tuple(shape):
        raise InputFileError(f"{frame.confidence}: the confidence image is {levels.shape[::-1]} but its depth is "
                             f"{tuple(shape)[::-1]} pixels (one channel of the depth's size expected)")
    if levels.max(initial=0) > CONFIDENCE_LEVELS:
        levels = np.rint(levels.astype(np.float64) * CONFIDENCE_LEVELS / 255.0)
    return levels.astype(np.int64)


def load_colour(frame: Frame, shape) -> np.ndarray | None:
    """The frame's colour image as ``(rows, columns, 3)`` uint8 at the depth's ``shape``; None
    without one."""
    if frame.image is None:
        return None
    from PIL import Image

    try:
        with Image.open(frame.image) as image:
            image = image.convert("RGB")
            if image.size != (shape[1], shape[0]):
                image = image.resize((shape[1], shape[0]), Image.BILINEAR)
            return np.asarray(image)
    except OSError as exc:
        raise InputFileError(f"{frame.image}: cannot read the colour image ({exc})") from None


# -- the layouts ----------------------------------------------------------------------------------


def _json(path: Path):
    try:
        return json.loads(path.read_text())
    except OSError as exc:
        raise InputFileError(f"{path}: cannot read ({exc.strerror or exc})") from None
    except ValueError as exc:
        raise InputFileError(f"{path}: not JSON ({exc})") from None


def _number(data: dict, key: str, path: Path, where: str = "", finite: bool = True) -> float:
    try:
        value = float(data[key])
    except KeyError:
        raise InputFileError(f"{path}: {where}no '{key}' (the intrinsics need fl_x/fx, fl_y/fy, cx, cy, w/width, "
                             f"h/height)") from None
    except (TypeError, ValueError):
        raise InputFileError(f"{path}: {where}'{key}' is not a number: {data[key]!r}") from None
    if finite and not np.isfinite(value):
        raise InputFileError(f"{path}: {where}'{key}' is not finite")
    return value


def _check_pose_finite(pose: np.ndarray, path: Path, where: str, field) -> None:
    """Refuse a pose holding NaN or inf, naming the entry (``field(row, column)``) and its part:
    checked before rigidity, which a NaN anywhere would make a rotation error."""
    bad = np.argwhere(~np.isfinite(pose))
    if len(bad) == 0:
        return
    r, c = bad[0]
    part = "its last row" if r == 3 else f"its translation's {'xyz'[r]}" if c == 3 else "its rotation"
    raise InputFileError(f"{path}: {where}{field(r, c)} is {pose[r, c]} ({part}): a pose must be finite numbers, "
                         f"the camera-to-world matrix in metres; export the pose again, or remove the frame")


def _pinhole(data: dict, path: Path, keys, where: str = "", centre: float = 0.0) -> Intrinsics:
    """Intrinsics from ``keys`` (fx, fy, cx, cy, width, height) of ``data``, the principal point
    moved from a convention whose top-left pixel centre is at ``centre`` to tpvp's."""
    fx, fy, cx, cy, width, height = (_number(data, key, path, where) for key in keys)
    cx, cy = cx - centre, cy - centre
    if min(fx, fy, width, height) <= 0:
        raise InputFileError(f"{path}: {where}the focal lengths and the image size must be positive")
    return Intrinsics(fx, fy, cx, cy, int(width), int(height))


NERFSTUDIO_INTRINSICS = ("fl_x", "fl_y", "cx", "cy", "w", "h")


@READERS.register("nerfstudio", "transforms.json with depth_file_path per frame (OpenGL camera-to-world)")
def read_nerfstudio(folder: Path) -> list[Frame]:
    path = folder / "transforms.json"
    data = _json(path)
    if not isinstance(data, dict) or not isinstance(data.get("frames"), list):
        raise InputFileError(f"{path}: not a nerfstudio transforms.json (no 'frames' list)")
    frames = []
    for i, entry in enumerate(data["frames"]):
        where = f"frame {i}: "
        if not isinstance(entry, dict):
            raise InputFileError(f"{path}: {where}not a mapping")
        if "depth_file_path" not in entry:
            raise InputFileError(f"{path}: {where}no depth_file_path; fusion needs depth (ns-process-data writes it "
                                 f"for Polycam and Record3D captures)")
        image, depth = entry.get("file_path"), entry["depth_file_path"]
        for key, value in (("file_path", image), ("depth_file_path", depth)):
            if (value is not None or key == "depth_file_path") and not (isinstance(value, str) and value):
                raise InputFileError(f"{path}: {where}{key} must be a file's path, got {value!r}")
            if value:  # the frame's name is its image's (or depth's) stem: each file's stem follows the rule
                check_frame_name(Path(value).stem, f"{path}: {where}{key} {value!r}")
        name = Path(image or depth).stem
        where = f"frame {i} ({name}): "
        try:
            pose = np.asarray(entry["transform_matrix"], dtype=np.float64)
        except (KeyError, TypeError, ValueError):
            pose = np.zeros(0)
        if pose.shape != (4, 4):
            raise InputFileError(f"{path}: {where}transform_matrix must be a 4x4 matrix of numbers")
        _check_pose_finite(pose, path, where, lambda r, c: f"transform_matrix[{r}][{c}]")
        intrinsics = _pinhole({**data, **entry}, path, NERFSTUDIO_INTRINSICS, where, PIXEL_CENTRE)
        frames.append(Frame(name, folder / depth, switch_camera_axes(pose), intrinsics,
                            image=folder / image if image else None))
    return frames


def _polycam_root(folder: Path) -> Path:
    return folder / "keyframes" if (folder / "keyframes").is_dir() else folder


@READERS.register("polycam", "Polycam raw data: keyframes/ images, cameras, depth, confidence (ARKit, y up)")
def read_polycam(folder: Path) -> list[Frame]:
    root = _polycam_root(folder)
    corrected = (root / "corrected_cameras").is_dir()
    cameras = root / ("corrected_cameras" if corrected else "cameras")
    images = root / ("corrected_images" if corrected and (root / "corrected_images").is_dir() else "images")
    if not cameras.is_dir():
        raise InputFileError(f"{folder}: no keyframes/cameras/ folder (a Polycam raw-data export holds keyframes/ "
                             f"with images, cameras, depth and confidence)")
    frames = []
    for camera in sorted(cameras.glob("*.json"), key=_frame_order):
        check_frame_name(camera.stem, camera)
        data = _json(camera)
        if not isinstance(data, dict):
            raise InputFileError(f"{camera}: not a Polycam camera (a mapping of fx, fy, cx, cy, width, height, t_00..t_23)")
        # ns-process-data copies Polycam's principal point as nerfstudio's: read it the same way
        intrinsics = _pinhole(data, camera, ("fx", "fy", "cx", "cy", "width", "height"), centre=PIXEL_CENTRE)
        pose = np.eye(4)
        pose[:3] = [[_number(data, f"t_{r}{c}", camera, finite=False) for c in range(4)] for r in range(3)]
        _check_pose_finite(pose, camera, f"frame {camera.stem}: ", lambda r, c: f"t_{r}{c}")
        depth = root / "depth" / f"{camera.stem}.png"
        confidence = root / "confidence" / f"{camera.stem}.png"
        image = next((p for p in (images / f"{camera.stem}{s}" for s in (".jpg", ".jpeg", ".png")) if p.is_file()),
                     images / f"{camera.stem}.jpg")
        frames.append(Frame(camera.stem, depth, switch_camera_axes(ARKIT_TO_Z_UP @ pose), intrinsics, image=image,
                            confidence=confidence if confidence.is_file() else None))
    return frames


def _intrinsics_file(folder: Path, required: bool = True) -> Path | None:
    for name in ("intrinsics.yaml", "intrinsics.yml", "intrinsics.json"):
        if (folder / name).is_file():
            return folder / name
    if required:
        raise InputFileError(f"{folder}: no intrinsics.yaml (fx, fy, cx, cy, width, height of the depth images)")
    return None


def _frame_order(path: Path):
    """Numeric names (timestamps, frame numbers) in numeric order, the others after them by name."""
    stem = path.stem
    return (0, float(stem), stem) if stem.replace(".", "", 1).isdigit() else (1, 0.0, stem)


def _read_pose(path: Path, name: str) -> np.ndarray:
    try:
        pose = np.loadtxt(path, dtype=np.float64, ndmin=2)
    except (OSError, ValueError) as exc:
        raise InputFileError(f"{path}: not a 4x4 matrix of numbers ({exc})") from None
    if pose.shape != (4, 4):
        raise InputFileError(f"{path}: a pose is a 4x4 camera-to-world matrix (4 lines of 4 numbers), got "
                             f"{pose.shape[0]} x {pose.shape[1]}")
    _check_pose_finite(pose, path, f"frame {name}: ", lambda r, c: f"line {r + 1}, number {c + 1}")
    return pose


@READERS.register("depth", "intrinsics.yaml, depth/, poses/ (OpenCV camera-to-world 4x4), optional color/, confidence/")
def read_depth_folder(folder: Path) -> list[Frame]:
    intrinsics, depth_scale = read_intrinsics(_intrinsics_file(folder))
    depths = sorted([p for p in (folder / "depth").glob("*") if p.suffix.lower() in (".png", ".npy")],
                    key=_frame_order) if (folder / "depth").is_dir() else []
    if not depths:
        raise InputFileError(f"{folder}/depth: no depth images (.png in millimetres or .npy in metres)")
    poses = folder / ("poses" if (folder / "poses").is_dir() else "pose")
    frames = []
    for depth in depths:
        check_frame_name(depth.stem, depth)
        pose = poses / f"{depth.stem}.txt"
        if not pose.is_file():
            raise InputFileError(f"{pose}: missing: every depth image needs its pose (poses/NAME.txt, a 4x4 "
                                 f"camera-to-world matrix)")
        image = next((p for p in (folder / "color" / f"{depth.stem}{s}" for s in (".png", ".jpg", ".jpeg"))
                      if p.is_file()), None)
        confidence = folder / "confidence" / f"{depth.stem}.png"
        frames.append(Frame(depth.stem, depth, _read_pose(pose, depth.stem), intrinsics, depth_scale, image,
                            confidence if confidence.is_file() else None))
    return frames

