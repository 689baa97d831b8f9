"""Geometric information gain of candidate views and the next best view (docs/sensor.md#information-gain).

A view casts one ray per pixel ``(u, v)`` with ``u, v = 0, stride, 2 stride, ...`` (every 4th
pixel for single plants) through the occupancy map; a ray walks the map's voxels until the first
occupied one (or the map's end, or the maximum range). The gain is the number of distinct unknown
voxels that any ray of the view visits (optionally, the expected number seen when unknown voxels
occlude with probability ``1 - unknown_visibility``). Ray directions are those of
:func:`tpvp.sensor.camera.pixel_ray_directions`, bit for bit.
"""

from __future__ import annotations


import numpy as np
from numba import njit, prange

from tpvp.errors import ConfigError
from tpvp.nbv.occupancy import MODE_GAIN, MODE_VISIBILITY, OccupancyMap, pixel_ray, walk
from tpvp.sensor.camera import D435, Intrinsics, look_at_rotations


@njit(cache=True, parallel=True)
def _gains(positions, rotations, fx, fy, cx, cy, width, height, stride, max_range, state, lo, res,
           visibility, out):
    ncols = (width + stride - 1) // stride
    nrows = (height + stride - 1) // stride
    mode = MODE_VISIBILITY if visibility > 0.0 else MODE_GAIN
    tag = visibility if visibility > 0.0 else 1.0
    no_keys = np.zeros(0, dtype=np.int64)
    for v in prange(positions.shape[0]):
        ox, oy, oz = positions[v, 0], positions[v, 1], positions[v, 2]
        rot = rotations[v]
        # Per view and voxel: 1 once counted (each unknown voxel counts once), or best visibility.
        stamp = np.zeros(state.size)
        count = 0
        for r in range(nrows):
            yn = (np.float64(r * stride) - cy) / fy
            for c in range(ncols):
                dx, dy, dz, t_stop = pixel_ray(rot, c, stride, yn, cx, fx, max_range)
                count += walk(ox, oy, oz, dx, dy, dz, t_stop, state, lo[0], lo[1], lo[2], res,
                              mode, True, 0, 0, 0, stamp, tag, no_keys)
        out[v] = stamp.sum() if visibility > 0.0 else count


def information_gain(occupancy: OccupancyMap, positions, look_ats, stride: int = 4,
                     max_range: float = 1.0, intrinsics: Intrinsics = D435,
                     unknown_visibility: float | None = None) -> np.ndarray:
    """Gain ``(V,)`` of each candidate view (position + look-at) on ``occupancy``.

    Default: ``int64`` counts of distinct unknown voxels visited. With ``unknown_visibility``
    ``p`` in (0, 1), the probability that an unknown voxel lets a ray through, the expected
    number of unknown voxels seen (``float64``): a ray sees its ``n``-th unknown voxel (from 0)
    with probability ``p ** n``, and a voxel counts with its largest probability over the view's
    rays.
    """
    if int(stride) != stride or int(stride) < 1:
        raise ConfigError(f"pixel stride must be a positive integer, got {stride!r}")
    if not (max_range > 0):
        raise ConfigError(f"max_range must be > 0 m, got {max_range!r}")
    if unknown_visibility is None:
        visibility = 0.0
    elif 0.0 < unknown_visibility < 1.0:
        visibility = float(unknown_visibility)
    else:
        raise ConfigError(f"unknown_visibility must be in (0, 1) or None, got {unknown_visibility!r}")
    positions = np.asarray(positions, dtype=np.float64)
    if positions.ndim == 1:
        positions = positions.reshape(1, -1)
    if positions.ndim != 2 or positions.shape[1] != 3:
        raise ConfigError(f"view positions must be a (V, 3) array, got shape {positions.shape}")
    try:
        look_ats = np.broadcast_to(np.asarray(look_ats, dtype=np.float64).reshape(-1, 3), positions.shape)
    except ValueError:
        raise ConfigError(
            f"look-ats of shape {np.shape(look_ats)} do not match {len(positions)} view positions") from None
    rotations = look_at_rotations(positions, look_ats)  # validates finiteness and zero length
    out = np.zeros(len(positions), dtype=np.float64 if visibility else np.int64)
    if len(positions):
        k = intrinsics
        # Writable C-ordered copies: numba compiles a kernel once per argument type, and read-only
        # arrays (a view space's positions) are a type of their own.
        _gains(np.array(positions, order="C"), np.array(rotations, order="C"), k.fx, k.fy, k.cx,
               k.cy, int(k.width), int(k.height), int(stride), float(max_range),
               # The map's state is read-only and the shared walker is typed for writable arrays;
               # the copy (tens of kB) is not written to.
               np.array(occupancy.state),
               occupancy.origin_key, occupancy.resolution, visibility, out)
    return out


def next_best_view(occupancy: OccupancyMap, positions, look_ats, executed=(), **gain_options):
    """``(index, gains)``: the non-executed view of largest gain (ties: lowest index).

    ``gains`` holds every view's gain, executed ones included; ``gain_options`` go to
    :func:`information_gain`.
    """
    gains = information_gain(occupancy, positions, look_ats, **gain_options)
    done = np.asarray(sorted(executed) if isinstance(executed, (set, frozenset)) else executed,
                      dtype=np.int64).reshape(-1)
    if done.size and (done.min() < 0 or done.max() >= len(gains)):
        raise ConfigError(f"executed view indices {done.tolist()} out of range for {len(gains)} views")
    candidates = np.ones(len(gains), dtype=bool)
    candidates[done] = False
    if not candidates.any():
        raise ConfigError(f"no candidate view left: all {len(gains)} views are executed")
    masked = np.where(candidates, gains, -1)
    return int(np.argmax(masked)), gains  # argmax returns the first maximum
