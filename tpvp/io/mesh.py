"""Meshes (.obj .stl .off .glb) read with trimesh and sampled on their surface into a cloud."""

from __future__ import annotations

import io
import logging
from pathlib import Path

import numpy as np

from tpvp.errors import InputFileError, PointCloudError
from tpvp.io.files import check_input_file, cloud_extension, read_input_bytes

log = logging.getLogger(__name__)

MESH_EXTENSIONS = (".obj", ".stl", ".off", ".glb")


def read_mesh(path: Path, return_labels: bool, mesh_samples: int, seed: int):
    """``(points, None)``: ``mesh_samples`` points sampled on the mesh's surface (deterministic
    for a given ``seed``), or its vertices when it has no faces. Meshes carry no labels."""
    import trimesh  # imported lazily: only meshes need it

    ext, compressed = cloud_extension(path)
    if compressed:
        source, kwargs = io.BytesIO(read_input_bytes(path)), {"file_type": ext.lstrip(".")}
    else:
        check_input_file(path)
        source, kwargs = str(path), {}
    try:
        mesh = trimesh.load(source, force="mesh", process=False, **kwargs)
    except Exception as exc:  # trimesh raises many unrelated types on bad files
        reason = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise InputFileError(f"{path}: cannot read mesh: {reason}") from None
    vertices = np.asarray(getattr(mesh, "vertices", np.empty((0, 3))), dtype=np.float64)
    faces = np.asarray(getattr(mesh, "faces", np.empty((0, 3))))
    if len(faces) == 0:
        if len(vertices) == 0:
            raise PointCloudError(f"{path}: the mesh holds no geometry")
        log.info("%s: mesh has no faces; returning its %d vertices", path, len(vertices))
        return vertices, None
    if not np.isfinite(vertices).all():
        raise PointCloudError(f"{path}: mesh vertices contain NaN/inf")
    if not mesh.area > 0:
        raise PointCloudError(f"{path}: the mesh has zero surface area; cannot sample it")
    pts, _ = trimesh.sample.sample_surface(mesh, int(mesh_samples), seed=seed)
    return np.asarray(pts, dtype=np.float64), None
