"""Exact voxel ray traversal (Amanatides-Woo DDA) with empty-space skipping, in numba.

Semantics shared with the brute-force reference (:mod:`tpvp.sensor.bruteforce`): a ray
``o + t d`` (``t >= 0``) visits the voxels it passes through in order; it reports the first occupied
voxel, which is observed if its centre lies within the maximum range. The DDA leaves voxel ``k`` along
one axis at ``t = ((k + 1) res - o) / d`` (``d > 0``) or ``(k res - o) / d`` (``d < 0``); these
closed-form event times (never accumulated sums) are compared, ties going to the lowest axis.
Times are computed with the reciprocal ``inv = 1 / d`` (a multiplication, not a division, per
event); the brute force uses the same expressions, so both agree bit for bit.

Skipping is exact: every voxel closer (Chebyshev) than the grid's clearance value is empty, so the
ray may jump to a parameter ``t0`` inside that empty cube. The state after the jump is rebuilt from
the same event times ("all events with ``t < t0`` done"), so the DDA continues along exactly the
voxels it would have visited without the jump; only empty voxels are skipped.
"""

from __future__ import annotations

import numpy as np
from numba import njit

MISS = -1


@njit(cache=True, inline="always")
def event_time(k, step, res, o, inv):
    """Ray parameter at which the ray leaves voxel ``k`` along one axis (``inv = 1 / d``)."""
    if step > 0:
        return ((k + 1) * res - o) * inv
    if step < 0:
        return (k * res - o) * inv
    return np.inf


@njit(cache=True)
def _key_after(o, d, inv, step, k0, t0, res):
    """Voxel index along one axis once every boundary event with ``t < t0`` has been processed."""
    if step == 0:
        return k0
    k = np.int64(np.floor((o + t0 * d) / res))
    if step > 0:
        if k < k0:
            k = k0
        while k > k0 and event_time(k - 1, 1, res, o, inv) >= t0:
            k -= 1
        while event_time(k, 1, res, o, inv) < t0:
            k += 1
    else:
        if k > k0:
            k = k0
        while k < k0 and event_time(k + 1, -1, res, o, inv) >= t0:
            k += 1
        while event_time(k, -1, res, o, inv) < t0:
            k -= 1
    return k


@njit(cache=True, inline="always")
def _sign(x):
    if x > 0:
        return 1
    if x < 0:
        return -1
    return 0


@njit(cache=True)
def cast_ray(ox, oy, oz, dx, dy, dz, index, clearance, lo0, lo1, lo2, res, max_range_sq, t_stop):
    """Id of the first occupied voxel hit by ray ``o + t d`` (within range), else ``MISS``.

    The walk gives up (MISS) once it would enter voxels beyond ``t = t_stop`` (use ``np.inf`` for
    the full ray); callers use this when nothing beyond that point can matter.
    """
    n0, n1, n2 = index.shape
    sx, sy, sz = _sign(dx), _sign(dy), _sign(dz)
    inv_x = 1.0 / dx if sx != 0 else 0.0
    inv_y = 1.0 / dy if sy != 0 else 0.0
    inv_z = 1.0 / dz if sz != 0 else 0.0
    kx0 = np.int64(np.floor(ox / res))
    ky0 = np.int64(np.floor(oy / res))
    kz0 = np.int64(np.floor(oz / res))
    kx, ky, kz = kx0, ky0, kz0
    if not (lo0 <= kx0 < lo0 + n0 and lo1 <= ky0 < lo1 + n1 and lo2 <= kz0 < lo2 + n2):
        # Start where the ray enters the grid box shrunk by half a voxel; the padding voxels
        # around the occupied box are empty, so nothing before that point can be hit.
        t_enter = 0.0
        t_exit = np.inf
        for axis in range(3):
            if axis == 0:
                o, d, inv, lo, n = ox, dx, inv_x, lo0, n0
            elif axis == 1:
                o, d, inv, lo, n = oy, dy, inv_y, lo1, n1
            else:
                o, d, inv, lo, n = oz, dz, inv_z, lo2, n2
            low = (lo + 0.5) * res
            high = (lo + n - 0.5) * res
            if d == 0.0:
                if o < low or o > high:
                    return MISS
            else:
                t1 = (low - o) * inv
                t2 = (high - o) * inv
                if t1 > t2:
                    t1, t2 = t2, t1
                t_enter = max(t_enter, t1)
                t_exit = min(t_exit, t2)
        if t_enter > t_exit:
            return MISS
        kx = _key_after(ox, dx, inv_x, sx, kx0, t_enter, res)
        ky = _key_after(oy, dy, inv_y, sy, ky0, t_enter, res)
        kz = _key_after(oz, dz, inv_z, sz, kz0, t_enter, res)
    tx = event_time(kx, sx, res, ox, inv_x)
    ty = event_time(ky, sy, res, oy, inv_y)
    tz = event_time(kz, sz, res, oz, inv_z)
    while True:
        ix, iy, iz = kx - lo0, ky - lo1, kz - lo2
        if ix < 0 or iy < 0 or iz < 0 or ix >= n0 or iy >= n1 or iz >= n2:
            return MISS  # left the box; it is convex, so the ray never comes back
        # Clearance is 0 exactly on occupied voxels: one byte read per step, the id only on a hit.
        m = np.int64(clearance[ix, iy, iz])
        if m == 0:
            cx = (kx + 0.5) * res - ox
            cy = (ky + 0.5) * res - oy
            cz = (kz + 0.5) * res - oz
            if cx * cx + cy * cy + cz * cz > max_range_sq:
                return MISS
            return index[ix, iy, iz]
        if m >= 3:
            # Exit of the empty cube (half-width m-1 voxels) shrunk by half a voxel. Any m >= 2
            # is exact; for m = 2 the jump spans ~1.5 voxels and plain steps are cheaper.
            t0 = np.inf
            if sx > 0:
                t0 = min(t0, ((kx + m - 0.5) * res - ox) * inv_x)
            elif sx < 0:
                t0 = min(t0, ((kx - m + 1.5) * res - ox) * inv_x)
            if sy > 0:
                t0 = min(t0, ((ky + m - 0.5) * res - oy) * inv_y)
            elif sy < 0:
                t0 = min(t0, ((ky - m + 1.5) * res - oy) * inv_y)
            if sz > 0:
                t0 = min(t0, ((kz + m - 0.5) * res - oz) * inv_z)
            elif sz < 0:
                t0 = min(t0, ((kz - m + 1.5) * res - oz) * inv_z)
            if t0 > t_stop:
                return MISS
            kx = _key_after(ox, dx, inv_x, sx, kx0, t0, res)
            ky = _key_after(oy, dy, inv_y, sy, ky0, t0, res)
            kz = _key_after(oz, dz, inv_z, sz, kz0, t0, res)
            tx = event_time(kx, sx, res, ox, inv_x)
            ty = event_time(ky, sy, res, oy, inv_y)
            tz = event_time(kz, sz, res, oz, inv_z)
            continue
        if tx <= ty and tx <= tz:
            if tx > t_stop:
                return MISS
            kx += sx
            tx = event_time(kx, sx, res, ox, inv_x)
        elif ty <= tz:
            if ty > t_stop:
                return MISS
            ky += sy
            ty = event_time(ky, sy, res, oy, inv_y)
        else:
            if tz > t_stop:
                return MISS
            kz += sz
            tz = event_time(kz, sz, res, oz, inv_z)
