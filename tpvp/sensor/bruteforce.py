"""Brute-force reference of both measurement models, in plain numpy.

Every ray marches voxel by voxel from the camera (no empty-space skipping, no dense grid, no
z-buffer): occupancy is looked up in the sorted array of occupied voxel codes. Only for tests and
benchmarks; the numba kernels must reproduce these hit sets exactly.
"""

from __future__ import annotations

import numpy as np

from tpvp.scene import voxels
from tpvp.scene.grid import OccupancyGrid
from tpvp.sensor.camera import D435, Intrinsics, look_at_rotation, pixel_ray_directions


def _event_times(k, step, res, origin, inverse):
    up = ((k + 1) * res - origin) * inverse
    down = (k * res - origin) * inverse
    return np.where(step > 0, up, np.where(step < 0, down, np.inf))


def march_rays(grid: OccupancyGrid, origin, directions, max_range: float) -> np.ndarray:
    """Id of the first occupied voxel along each ray ``origin + t * direction`` (-1 if none)."""
    res = grid.resolution
    origin = np.asarray(origin, dtype=np.float64).reshape(1, 3)
    directions = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    codes = voxels.encode_keys(grid.keys)
    order = np.argsort(codes)
    sorted_codes = codes[order]
    box_lo, box_hi = grid.keys.min(axis=0), grid.keys.max(axis=0)

    n = len(directions)
    step = np.sign(directions).astype(np.int64)
    k = np.repeat(np.floor(origin / res).astype(np.int64), n, axis=0)
    with np.errstate(divide="ignore"):
        inverse = np.where(step != 0, 1.0 / np.where(step != 0, directions, 1.0), 0.0)
    t_next = _event_times(k, step, res, origin, inverse)
    result = np.full(n, -1, dtype=np.int64)
    active = np.arange(n)
    while active.size:
        ka = k[active]
        code = voxels.encode_keys(ka)
        pos = np.minimum(np.searchsorted(sorted_codes, code), len(sorted_codes) - 1)
        occupied = sorted_codes[pos] == code
        if occupied.any():
            hit_rays = active[occupied]
            ids = order[pos[occupied]]
            offset = voxels.key_centres(ka[occupied], res) - origin
            in_range = (offset**2).sum(axis=1) <= max_range**2
            result[hit_rays[in_range]] = ids[in_range]
        # A ray outside the occupied box and moving away from it (or parallel) can never hit.
        sa = step[active]
        gone = np.any(((ka < box_lo) & (sa <= 0)) | ((ka > box_hi) & (sa >= 0)), axis=1)
        keep = ~occupied & ~gone
        active = active[keep]
        if not active.size:
            break
        tn = t_next[active]
        axis = np.argmin(tn, axis=1)  # first minimum: ties go to the lowest axis, as in the DDA
        rows = np.arange(active.size)
        k[active, axis] += step[active, axis]
        new_k = k[active, axis]
        inv = inverse[active, axis]
        o = origin[0, axis]
        s = step[active, axis]
        t = np.where(s > 0, ((new_k + 1) * res - o) * inv, (new_k * res - o) * inv)
        tn[rows, axis] = t
        t_next[active] = tn
    return result


def reference_observation(grid: OccupancyGrid, position, look_at, max_range: float = 1.0,
                          intrinsics: Intrinsics = D435) -> np.ndarray:
    """Sorted countable voxel ids seen by the voxel-driven model (one ray per in-frustum centre)."""
    position = np.asarray(position, dtype=np.float64).reshape(3)
    rot = look_at_rotation(position, look_at)
    centres = grid.centres
    rel = centres - position
    rx, ry, rz = rel[:, 0], rel[:, 1], rel[:, 2]
    # Element-wise, in the kernel's order, so both decide the frustum border identically.
    zc = rot[0, 2] * rx + rot[1, 2] * ry + rot[2, 2] * rz
    xc = rot[0, 0] * rx + rot[1, 0] * ry + rot[2, 0] * rz
    yc = rot[0, 1] * rx + rot[1, 1] * ry + rot[2, 1] * rz
    with np.errstate(divide="ignore", invalid="ignore"):
        u = intrinsics.fx * xc / zc + intrinsics.cx
        v = intrinsics.fy * yc / zc + intrinsics.cy
    inside = (zc > 0) & (u >= 0) & (u <= intrinsics.width) & (v >= 0) & (v <= intrinsics.height)
    hits = march_rays(grid, position, rel[inside], max_range)
    hits = np.unique(hits[hits >= 0])
    return hits[grid.countable[hits]]


def pixel_observation(grid: OccupancyGrid, position, look_at, max_range: float = 1.0,
                      intrinsics: Intrinsics = D435, stride: int = 1, return_image: bool = False):
    """Sorted countable voxel ids seen by one ray per pixel (optionally the per-pixel hit image)."""
    position = np.asarray(position, dtype=np.float64).reshape(3)
    rot = look_at_rotation(position, look_at)
    directions = pixel_ray_directions(rot, intrinsics, stride)
    hits_per_pixel = march_rays(grid, position, directions, max_range)
    hits = np.unique(hits_per_pixel[hits_per_pixel >= 0])
    hits = hits[grid.countable[hits]]
    if return_image:
        shape = (-(-intrinsics.height // stride), -(-intrinsics.width // stride))
        return hits, hits_per_pixel.reshape(shape)
    return hits
