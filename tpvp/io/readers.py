"""The point-cloud reader: a registry of readers by file extension, and ``read_point_cloud``.

Each format family has its module (:mod:`~tpvp.io.ply`, :mod:`~tpvp.io.pcd`,
:mod:`~tpvp.io.text`, :mod:`~tpvp.io.mesh`), each reading a file into points in the file's units;
:func:`read_point_cloud` picks the reader by extension, drops or refuses NaN/inf points and
converts to metres (:mod:`tpvp.io.units`). Every format can be read gzip-compressed
(``scan.ply.gz``, ``scan.xyz.gz``, ``mesh.obj.gz``, ...): the file is decompressed in memory and
parsed like the plain file, errors still name it (:mod:`tpvp.io.files`).
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np

from tpvp.errors import ConfigError, InputFileError, PointCloudError
from tpvp.io.files import check_input_file, cloud_extension
from tpvp.io.mesh import MESH_EXTENSIONS, read_mesh
from tpvp.io.pcd import PCD_EXTENSIONS, read_pcd
from tpvp.io.ply import PLY_EXTENSIONS, read_ply
from tpvp.io.text import TEXT_EXTENSIONS, read_text_cloud
from tpvp.io.units import UNITS, as_points, in_metres, unit_choice
from tpvp.registry import Registry

#: Suffix -> reader. Every reader is ``reader(path, return_labels, mesh_samples, seed)`` and
#: returns ``(points in file units, integer labels or None)``; a new format is one module and one
#: line here.
READERS = Registry("point-cloud reader")
_FORMATS = (
    (PLY_EXTENSIONS, read_ply),
    (PCD_EXTENSIONS, read_pcd),
    (TEXT_EXTENSIONS, read_text_cloud),
    (MESH_EXTENSIONS, read_mesh),
)
for _extensions, _reader in _FORMATS:
    for _extension in _extensions:
        READERS.register(_extension)(_reader)

READ_EXTENSIONS = tuple(extension for extensions, _ in _FORMATS for extension in extensions)
#: Every readable format also gzip-compressed (``.ply.gz``, ``.xyz.gz``, ...).
GZIP_READ_EXTENSIONS = tuple(e + ".gz" for e in READ_EXTENSIONS)


def _drop_nonfinite(path, pts, labels, drop_invalid):
    bad = ~np.isfinite(pts).all(axis=1)
    nbad = int(bad.sum())
    if not nbad:
        return pts, labels
    if not drop_invalid:
        first = int(np.flatnonzero(bad)[0])
        raise PointCloudError(
            f"{path}: {nbad:,} of {len(pts):,} points {'has' if nbad == 1 else 'have'} NaN/inf coordinates "
            f"(first at point {first + 1:,}); remove them, or pass --drop-invalid (tpvp plan, tpvp session "
            f"start/add) / drop_invalid=True (tpvp.io.read_point_cloud)")
    warnings.warn(f"{path}: dropped {nbad:,} of {len(pts):,} points with NaN/inf coordinates",
                  stacklevel=3)
    keep = ~bad
    return pts[keep], (labels[keep] if labels is not None else None)


def read_point_cloud(path, units: str = "auto", return_labels: bool = False, *,
                     drop_invalid: bool = False, mesh_samples: int = 100_000, seed: int = 0,
                     return_units: bool = False):
    """Read a point cloud as float64 (N, 3) metres (``(points, labels or None)`` with
    ``return_labels``).

    Formats by extension (case-insensitive): .ply (ascii / binary LE / binary BE), .pcd (ascii,
    binary, binary_compressed), .xyz .txt .pts .csv (3+ columns: x y z, then an optional integer
    label), and meshes .obj .stl .off .glb, surface-sampled with ``mesh_samples`` points
    (deterministic for a given ``seed``); each of them also gzip-compressed (``.ply.gz``, ...).
    ``units``: "auto", "m" or "mm" (see :mod:`tpvp.io.units`). NaN/inf points raise PointCloudError unless
    ``drop_invalid`` is True. With ``return_units`` a :class:`UnitChoice` is appended to the
    result (``(points, choice)`` or ``(points, labels, choice)``); ``str(choice)`` reads
    ``auto -> mm (largest extent 230 mm)``.
    """
    if not isinstance(path, (str, os.PathLike)):
        raise ConfigError(f"path must be a file path, got {type(path).__name__}")
    if units not in UNITS:
        raise ConfigError(f"units must be one of {UNITS}, got {units!r}")
    if not isinstance(mesh_samples, (int, np.integer)) or isinstance(mesh_samples, bool) \
            or mesh_samples < 1:
        raise ConfigError(f"mesh_samples must be a positive integer, got {mesh_samples!r}")
    path = Path(path)
    check_input_file(path)  # before anything opens it: a FIFO would block, a device never end
    ext, compressed = cloud_extension(path)
    if ext not in READERS:
        what = f"{ext or '(none)'}.gz" if compressed else (ext or "(none)")
        raise InputFileError(f"{path}: unknown point-cloud extension {what!r} "
                             f"(supported: {' '.join(READ_EXTENSIONS)}, each optionally .gz)")
    pts, labels = READERS.get(ext)(path, return_labels, mesh_samples, seed)
    pts, labels = _drop_nonfinite(path, pts, labels, drop_invalid)
    if len(pts) == 0:
        raise PointCloudError(f"{path}: holds no points")
    choice = unit_choice(pts, units, source=path)
    pts = in_metres(as_points(pts), units, choice.used, path)
    out = (pts, labels) if return_labels else (pts,)
    if return_units:
        out = (*out, choice)
    return out if len(out) > 1 else out[0]
