"""Point clouds written atomically: PLY and PCD (binary or ascii) and text tables."""

from __future__ import annotations

import io
import os
from pathlib import Path

import numpy as np

from tpvp.errors import ConfigError, PointCloudError
from tpvp.io.atomic import atomic_write_bytes
from tpvp.io.text import TEXT_EXTENSIONS
from tpvp.io.units import as_points
from tpvp.registry import Registry

#: Suffix -> encoder. Every encoder is ``encode(points, labels, binary, fmt) -> bytes`` (``points``
#: already float32 or float64, ``labels`` int64 or None, ``fmt`` the text format of a coordinate);
#: a new format is one function and one registration here.
WRITERS = Registry("point-cloud writer")


def write_point_cloud(path, points, labels=None, binary: bool = True, *, dtype=None, colors=None) -> Path:
    """Write points (and optional integer labels, and for .ply optional ``(N, 3)`` uint8 RGB
    ``colors``) atomically; returns the path.

    By extension: .ply (binary little-endian, or ascii with ``binary=False``), .pcd (binary or
    ascii), .xyz/.txt/.pts/.csv text (``x y z [label]``; .csv comma-separated; .pts starts with
    the point count). ``dtype`` is "float64" or "float32"; the default (None) is float64
    (lossless) except for PCD, which gets float32 because PCL tools expect it and open3d 0.20
    reads binary ``F 8`` fields as zeros. Parent directories are created.
    """
    if not isinstance(path, (str, os.PathLike)):
        raise ConfigError(f"path must be a file path, got {type(path).__name__}")
    path = Path(path)
    ext = path.suffix.lower()
    if ext not in WRITERS:
        raise ConfigError(f"{path}: cannot write extension {ext or '(none)'!r} "
                          f"(supported: {' '.join(WRITE_EXTENSIONS)})")
    if dtype is None:
        dtype = "float32" if ext == ".pcd" else "float64"
    try:
        dt = np.dtype(dtype)
    except TypeError:
        dt = None
    if dt not in (np.dtype("f4"), np.dtype("f8")):
        raise ConfigError(f"dtype must be float32 or float64, got {dtype!r}")
    pts = as_points(points)
    if len(pts) == 0:
        raise PointCloudError(f"cannot write {path}: points is empty")
    if not np.isfinite(pts).all():
        nbad = int((~np.isfinite(pts).all(axis=1)).sum())
        raise PointCloudError(f"cannot write {path}: {nbad} points have NaN/inf coordinates")
    if labels is not None:
        labels = _integer_labels(labels, len(pts))
    fmt = "%.9g" if dt == np.float32 else "%.17g"
    if colors is None:
        data = WRITERS.get(ext)(pts.astype(dt), labels, binary, fmt)
    elif ext != ".ply":
        raise ConfigError(f"{path}: colours are written to .ply files only")
    else:
        data = encode_ply(pts.astype(dt), labels, binary, fmt, _colours(colors, len(pts)))
    atomic_write_bytes(path, data)
    return path


def _integer_labels(labels, n: int) -> np.ndarray:
    lab = np.asarray(labels)
    if lab.shape != (n,):
        raise ConfigError(f"labels must have shape ({n},), got {lab.shape}")
    if lab.dtype.kind not in "iu" and not (
            lab.dtype.kind in "fb" and np.isfinite(lab).all()
            and np.array_equal(lab, np.round(lab))):
        raise ConfigError("labels must be integers")
    lab = lab.astype(np.int64)
    if lab.size and (lab.min() < np.iinfo(np.int32).min or lab.max() > np.iinfo(np.int32).max):
        raise ConfigError("labels must fit in 32-bit integers")
    return lab


def _colours(colors, n: int) -> np.ndarray:
    rgb = np.asarray(colors)
    if rgb.shape != (n, 3) or rgb.dtype != np.uint8:
        raise ConfigError(f"colors must be an ({n}, 3) uint8 array, got {rgb.shape} {rgb.dtype}")
    return rgb


@WRITERS.register(".ply")
def encode_ply(pts: np.ndarray, labels, binary: bool, fmt: str, colors=None) -> bytes:
    ptype = "float" if pts.dtype == np.float32 else "double"
    header = [
        "ply",
        f"format {'binary_little_endian' if binary else 'ascii'} 1.0",
        "comment written by tpvp",
        f"element vertex {len(pts)}",
        *(f"property {ptype} {c}" for c in "xyz"),
        *(["property int label"] if labels is not None else []),
        *([f"property uchar {c}" for c in ("red", "green", "blue")] if colors is not None else []),
        "end_header",
    ]
    body = _packed(pts, labels, "<", "i4", colors) if binary else _text_body(pts, labels, fmt, " ", colors)
    return ("\n".join(header) + "\n").encode("ascii") + body


@WRITERS.register(".pcd")
def encode_pcd(pts: np.ndarray, labels, binary: bool, fmt: str) -> bytes:
    size = pts.dtype.itemsize
    fields, sizes, types = "x y z", [size] * 3, ["F"] * 3
    if labels is not None:
        fields += " label"
        sizes.append(4)
        # PCL's label is unsigned; negative labels (e.g. -1 = unlabelled) need a signed type.
        types.append("U" if labels.min() >= 0 else "I")
    n, k = len(pts), len(sizes)
    header = [
        "# .PCD v0.7 - Point Cloud Data file format",
        "VERSION 0.7",
        f"FIELDS {fields}",
        f"SIZE {' '.join(map(str, sizes))}",
        f"TYPE {' '.join(types)}",
        f"COUNT {' '.join(['1'] * k)}",
        f"WIDTH {n}",
        "HEIGHT 1",
        "VIEWPOINT 0 0 0 1 0 0 0",
        f"POINTS {n}",
        f"DATA {'binary' if binary else 'ascii'}",
    ]
    body = _packed(pts, labels, "<", "u4" if types[-1] == "U" else "i4") if binary else _text_body(pts, labels, fmt, " ")
    return ("\n".join(header) + "\n").encode("ascii") + body


def _text_encoder(extension: str):
    """``x y z [label]`` per line; .csv comma-separated; .pts starts with the point count."""
    def encode(pts: np.ndarray, labels, binary: bool, fmt: str) -> bytes:
        head = f"{len(pts)}\n".encode() if extension == ".pts" else b""
        return head + _text_body(pts, labels, fmt, "," if extension == ".csv" else " ")
    return encode


for _extension in TEXT_EXTENSIONS:
    WRITERS.register(_extension, "text: x y z [label]")(_text_encoder(_extension))
WRITE_EXTENSIONS = (".ply", ".pcd") + TEXT_EXTENSIONS


def _packed(pts: np.ndarray, labels, endian: str, label_code: str, colors=None) -> bytes:
    fields = [(c, endian + pts.dtype.str[1:]) for c in "xyz"]
    if labels is not None:
        fields.append(("label", endian + label_code))
    if colors is not None:
        fields += [(c, "u1") for c in ("red", "green", "blue")]
    rec = np.empty(len(pts), dtype=fields)
    for j, c in enumerate("xyz"):
        rec[c] = pts[:, j]
    if labels is not None:
        rec["label"] = labels
    if colors is not None:
        for j, c in enumerate(("red", "green", "blue")):
            rec[c] = colors[:, j]
    return rec.tobytes()


def _text_body(pts: np.ndarray, labels, fmt: str, delim: str, colors=None) -> bytes:
    buf = io.StringIO()
    columns, formats = [pts.astype(np.float64)], [fmt] * 3
    if labels is not None:
        columns.append(labels.astype(np.float64)[:, None])
        formats.append("%d")
    if colors is not None:
        columns.append(colors.astype(np.float64))
        formats += ["%d"] * 3
    np.savetxt(buf, np.column_stack(columns), fmt=formats, delimiter=delim)
    return buf.getvalue().encode("ascii")
