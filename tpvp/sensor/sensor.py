"""The virtual sensor: which ground-truth voxels a camera view observes.

Two measurement models over one :class:`~tpvp.scene.grid.OccupancyGrid` (see
:mod:`tpvp.sensor.kernels`): ``reference`` (default; the authors' voxel-driven simulator, behind
every number compared with the paper) and ``pixel`` (one ray per pixel, like a real depth camera).
"""

from __future__ import annotations

import numpy as np

from tpvp.errors import SensorError
from tpvp.numba_tools import run_workers
from tpvp.scene.grid import OccupancyGrid
from tpvp.sensor import kernels
from tpvp.sensor.camera import look_at_rotation
from tpvp.sensor.config import ROW_RANGE, SensorConfig

ROW_SENSOR = SensorConfig(max_range=ROW_RANGE)  # the reference model at the rows' range


def check_camera(grid: OccupancyGrid, position) -> np.ndarray:
    """Reject cameras placed inside an occupied voxel (the ray caster would see only that voxel)."""
    # A writable copy: numba compiles a kernel once per argument type, and read-only arrays (a
    # view space's positions) are a type of their own.
    position = np.array(position, dtype=np.float64).reshape(3)
    if not np.all(np.isfinite(position)):
        raise SensorError(f"camera position {position.tolist()} is not finite")
    local = np.floor(position / grid.resolution).astype(np.int64) - grid.origin_key
    if np.all((local >= 0) & (local < grid.index.shape)) and grid.index[tuple(local)] >= 0:
        raise SensorError(
            f"camera at {position.round(4).tolist()} m lies inside the geometry (an occupied voxel)"
        )
    return position


def _extras(grid: OccupancyGrid, pixel: bool = False) -> dict:
    # Derived arrays used by the kernels, computed once per grid and cached on the instance; the
    # exposed faces only once the pixel model needs them (a kernel the reference model never compiles).
    cache = grid.__dict__.setdefault("_kernel_cache", {})
    if not cache:
        cache["centres"] = np.ascontiguousarray(grid.centres)
        cache["lo"] = np.ascontiguousarray(grid.origin_key)
        cache["countable"] = np.ascontiguousarray(grid.countable)
        cache["keys"] = np.ascontiguousarray(grid.keys)
        counted = grid.keys[grid.countable] if grid.countable.any() else grid.keys
        cache["countable_box"] = np.concatenate(
            [(counted.min(axis=0) - 1) * grid.resolution, (counted.max(axis=0) + 2) * grid.resolution])
    if pixel and "exposed" not in cache:
        cache["exposed"] = kernels.exposed_faces(cache["keys"], grid.index, cache["lo"])
    return cache


def observe(grid: OccupancyGrid, position, look_at, config: SensorConfig = SensorConfig()) -> np.ndarray:
    """Sorted ids of the countable voxels observed from one view."""
    position = check_camera(grid, position)
    rotation = look_at_rotation(position, look_at)
    ex = _extras(grid, pixel=config.model == "pixel")
    k = config.intrinsics
    if config.model == "reference":
        first_hit = np.empty(grid.size, dtype=np.int64)
        kernels.reference_view(position, rotation, k.fx, k.fy, k.cx, k.cy, k.width, k.height,
                               ex["centres"], grid.index, grid.clearance, ex["lo"], grid.resolution,
                               float(config.max_range) ** 2, ex["countable"], ex["countable_box"], first_hit)
        return kernels.countable_hit_ids(first_hit, ex["countable"])
    seen = np.zeros(grid.size, dtype=np.bool_)
    stride = int(config.pixel_stride)
    shape = (-(-k.height // stride), -(-k.width // stride))
    scratch = _scratch(shape)
    kernels.pixel_view_seen(position, rotation, k.fx, k.fy, k.cx, k.cy, k.width, k.height, stride,
                            ex["keys"], ex["exposed"], grid.resolution, ex["centres"],
                            float(config.max_range) ** 2, ex["countable"], seen, *scratch)
    return np.flatnonzero(seen)


_SCRATCH: dict = {}  # numba kernels hold the GIL, so one pair per size is safe


def _scratch(shape):
    """Reusable z-buffer images for single-view rendering (one pair per image size)."""
    if shape not in _SCRATCH:
        _SCRATCH.clear()
        _SCRATCH[shape] = (np.empty(shape), np.empty(shape, dtype=np.int64))
    return _SCRATCH[shape]


def depth_image(grid: OccupancyGrid, position, look_at, config: SensorConfig = SensorConfig()):
    """Pixel model image: ``(depth, voxel_id)`` arrays over the strided pixel grid.

    ``depth`` is the camera-z depth of the first surface along each pixel ray (``inf`` where the
    ray sees nothing within range), ``voxel_id`` the id of that voxel (``-1`` for none).
    """
    position = check_camera(grid, position)
    rotation = look_at_rotation(position, look_at)
    ex = _extras(grid, pixel=True)
    k = config.intrinsics
    stride = int(config.pixel_stride)
    shape = (-(-k.height // stride), -(-k.width // stride))
    depth = np.empty(shape)
    hit = np.empty(shape, dtype=np.int64)
    kernels.pixel_view(position, rotation, k.fx, k.fy, k.cx, k.cy, stride, ex["keys"], ex["exposed"],
                       grid.resolution, 0, 0, depth, hit)
    found = hit >= 0
    offset = ex["centres"][hit[found]] - position
    too_far = (offset**2).sum(axis=1) > float(config.max_range) ** 2
    idx = np.flatnonzero(found.ravel())[too_far]
    hit.ravel()[idx] = -1
    depth.ravel()[idx] = np.inf
    return depth, hit


def observe_many(grid: OccupancyGrid, positions, look_ats, config: SensorConfig = SensorConfig()) -> np.ndarray:
    """Dense boolean matrix ``(views, voxels)``: which countable voxels each view observes (parallel
    over views); :func:`tpvp.visibility.visibility_matrix` gives the sparse form in chunks."""
    positions, rotations = view_poses(grid, positions, look_ats)
    return observe_poses(grid, positions, rotations, config)


def view_poses(grid: OccupancyGrid, positions, look_ats):
    """Validated ``(V, 3)`` positions and their ``(V, 3, 3)`` camera rotations."""
    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    look_ats = np.broadcast_to(np.asarray(look_ats, dtype=np.float64).reshape(-1, 3), positions.shape)
    for p in positions:
        check_camera(grid, p)
    rotations = [look_at_rotation(p, t) for p, t in zip(positions, look_ats)]
    return positions, (np.stack(rotations) if rotations else np.zeros((0, 3, 3)))


def observe_poses(grid: OccupancyGrid, positions, rotations,
                  config: SensorConfig = SensorConfig()) -> np.ndarray:
    """Dense boolean matrix ``(views, voxels)`` for views given as poses: ``(V, 3)`` positions and
    their ``(V, 3, 3)`` camera rotations, already checked (as :func:`view_poses` returns them).

    The work behind :func:`observe_many` and :func:`tpvp.visibility.visibility_matrix`.
    """
    ex = _extras(grid, pixel=config.model == "pixel")
    k = config.intrinsics
    seen = np.zeros((len(positions), grid.size), dtype=np.bool_)
    if len(positions) == 0:
        return seen
    # Writable C-ordered copies: one compiled kernel whatever the caller's arrays (see check_camera).
    positions = np.array(positions, dtype=np.float64, order="C")
    rotations = np.array(rotations, dtype=np.float64, order="C")
    if config.model == "reference":
        run_workers(kernels.reference_views, len(positions), positions, rotations, k.fx, k.fy, k.cx, k.cy,
                    k.width, k.height, ex["centres"], grid.index, grid.clearance, ex["lo"], grid.resolution,
                    float(config.max_range) ** 2, ex["countable"], ex["countable_box"], seen)
    else:
        run_workers(kernels.pixel_views, len(positions), positions, rotations, k.fx, k.fy, k.cx, k.cy,
                    k.width, k.height, int(config.pixel_stride), ex["keys"], ex["exposed"], grid.resolution,
                    ex["centres"], float(config.max_range) ** 2, ex["countable"], seen)
    return seen
