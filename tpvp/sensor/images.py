"""A depth camera's files: pinhole intrinsics (YAML/JSON) and depth images (``.npy`` metres, 16-bit
``.png`` millimetres), read with one clear error naming the file for anything else."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tpvp.errors import InputFileError
from tpvp.sensor.camera import Intrinsics


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
