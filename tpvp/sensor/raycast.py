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

The stepping is shared with the occupancy map of :mod:`tpvp.nbv.occupancy` (one DDA for both):
``ray_setup`` (step signs, reciprocals, start voxel), ``slab`` (entry interval of a box),
``keys_after`` (state after every event before a ray parameter, the exact jump), ``event_times``
and ``dda_step`` (one step, ties to the lowest axis). They are separate kernels, inlined by LLVM
when a caller is optimised (numba's own ``inline="always"`` retyped them at every call site: a
third more compile time, and no faster code).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from tpvp.numba_tools import JIT
from tpvp.scene.voxels import encode_key

MISS = -1

# Code of a voxel key (:func:`tpvp.scene.voxels.encode_key`, the same function) inside kernels.
encode_key_jit = njit(**JIT)(encode_key)


@njit(**JIT)
def event_time(k, step, res, o, inv):
    """Ray parameter at which the ray leaves voxel ``k`` along one axis (``inv = 1 / d``)."""
    if step > 0:
        return ((k + 1) * res - o) * inv
    if step < 0:
        return (k * res - o) * inv
    return np.inf


@njit(**JIT)
def key_after(o, d, inv, step, k0, t0, res):
    """Voxel index along one axis once every boundary event with ``t < t0`` has been processed.

    ``k0`` is the start voxel ``floor(o / res)``; the result is the index that the plain DDA walk
    from ``k0`` holds after all its events before ``t0`` along this axis (closed-form event times,
    so it is exact, not a rounding of ``o + t0 d``).
    """
    if step == 0:
        return k0
    k = np.int64(np.floor((o + t0 * d) / res))
    # step is 1 or -1 in the branches (passed on, not as a literal: one compiled event_time)
    if step > 0:
        if k < k0:
            k = k0
        while k > k0 and event_time(k - 1, step, res, o, inv) >= t0:
            k -= 1
        while event_time(k, step, res, o, inv) < t0:
            k += 1
    else:
        if k > k0:
            k = k0
        while k < k0 and event_time(k + 1, step, res, o, inv) >= t0:
            k += 1
        while event_time(k, step, res, o, inv) < t0:
            k -= 1
    return k


@njit(**JIT)
def _sign(x):
    if x > 0:
        return 1
    if x < 0:
        return -1
    return 0


@njit(**JIT)
def ray_setup(ox, oy, oz, dx, dy, dz, res):
    """Start of the DDA along ``o + t d``: ``(sx, sy, sz, inv_x, inv_y, inv_z, kx, ky, kz)``.

    Step signs per axis (0 for a zero component), reciprocals ``1 / d`` (0 where ``d = 0``) and
    the key of the voxel holding the origin.
    """
    sx, sy, sz = _sign(dx), _sign(dy), _sign(dz)
    inv_x = 1.0 / dx if sx != 0 else 0.0
    inv_y = 1.0 / dy if sy != 0 else 0.0
    inv_z = 1.0 / dz if sz != 0 else 0.0
    kx = np.int64(np.floor(ox / res))
    ky = np.int64(np.floor(oy / res))
    kz = np.int64(np.floor(oz / res))
    return sx, sy, sz, inv_x, inv_y, inv_z, kx, ky, kz


@njit(**JIT)
def slab(o, d, inv, low, high, parallel_inside):
    """Ray-parameter interval ``(t_in, t_out)`` inside the slab ``low <= x <= high`` of one axis.

    For ``d = 0`` the ray is either always inside (``parallel_inside``, decided by the caller) or
    never (an empty interval).
    """
    if d > 0.0:
        return (low - o) * inv, (high - o) * inv
    if d < 0.0:
        return (high - o) * inv, (low - o) * inv
    if parallel_inside:
        return -np.inf, np.inf
    return np.inf, -np.inf


@njit(**JIT)
def keys_after(ox, oy, oz, dx, dy, dz, inv_x, inv_y, inv_z, sx, sy, sz, kx0, ky0, kz0, t0, res):
    """Voxel ``(kx, ky, kz)`` of the DDA from ``(kx0, ky0, kz0)`` after every event with ``t < t0``
    (an exact jump, see :func:`key_after`)."""
    return (key_after(ox, dx, inv_x, sx, kx0, t0, res),
            key_after(oy, dy, inv_y, sy, ky0, t0, res),
            key_after(oz, dz, inv_z, sz, kz0, t0, res))


@njit(**JIT)
def event_times(kx, ky, kz, sx, sy, sz, ox, oy, oz, inv_x, inv_y, inv_z, res):
    """Ray parameters ``(tx, ty, tz)`` at which the ray leaves voxel ``(kx, ky, kz)`` per axis."""
    return (event_time(kx, sx, res, ox, inv_x), event_time(ky, sy, res, oy, inv_y),
            event_time(kz, sz, res, oz, inv_z))


@njit(**JIT)
def dda_step(kx, ky, kz, tx, ty, tz, sx, sy, sz, ox, oy, oz, inv_x, inv_y, inv_z, res, t_stop):
    """One DDA step: ``(moved, kx, ky, kz, tx, ty, tz)``.

    Leaves the current voxel along the axis of the earliest event (ties to the lowest axis);
    ``moved`` is False (state unchanged) when that event lies beyond ``t_stop``.
    """
    if tx <= ty and tx <= tz:
        if tx > t_stop:
            return False, kx, ky, kz, tx, ty, tz
        kx += sx
        tx = event_time(kx, sx, res, ox, inv_x)
    elif ty <= tz:
        if ty > t_stop:
            return False, kx, ky, kz, tx, ty, tz
        ky += sy
        ty = event_time(ky, sy, res, oy, inv_y)
    else:
        if tz > t_stop:
            return False, kx, ky, kz, tx, ty, tz
        kz += sz
        tz = event_time(kz, sz, res, oz, inv_z)
    return True, kx, ky, kz, tx, ty, tz


@njit(**JIT)
def cast_ray(ox, oy, oz, dx, dy, dz, index, clearance, lo0, lo1, lo2, res, max_range_sq, t_stop):
    """Id of the first occupied voxel hit by ray ``o + t d`` (within range), else ``MISS``.

    The walk gives up (MISS) once it would enter voxels beyond ``t = t_stop`` (use ``np.inf`` for
    the full ray); callers use this when nothing beyond that point can matter.
    """
    n0, n1, n2 = index.shape
    sx, sy, sz, inv_x, inv_y, inv_z, kx0, ky0, kz0 = ray_setup(ox, oy, oz, dx, dy, dz, res)
    kx, ky, kz = kx0, ky0, kz0
    if not (lo0 <= kx0 < lo0 + n0 and lo1 <= ky0 < lo1 + n1 and lo2 <= kz0 < lo2 + n2):
        # Start where the ray enters the grid box shrunk by half a voxel; the padding voxels
        # around the occupied box are empty, so nothing before that point can be hit.
        low0, high0 = (lo0 + 0.5) * res, (lo0 + n0 - 0.5) * res
        low1, high1 = (lo1 + 0.5) * res, (lo1 + n1 - 0.5) * res
        low2, high2 = (lo2 + 0.5) * res, (lo2 + n2 - 0.5) * res
        a0, b0 = slab(ox, dx, inv_x, low0, high0, low0 <= ox <= high0)
        a1, b1 = slab(oy, dy, inv_y, low1, high1, low1 <= oy <= high1)
        a2, b2 = slab(oz, dz, inv_z, low2, high2, low2 <= oz <= high2)
        t_enter = max(0.0, max(a0, max(a1, a2)))
        t_exit = min(b0, min(b1, b2))
        if t_enter > t_exit:
            return MISS
        kx, ky, kz = keys_after(ox, oy, oz, dx, dy, dz, inv_x, inv_y, inv_z, sx, sy, sz,
                                kx0, ky0, kz0, t_enter, res)
    tx, ty, tz = event_times(kx, ky, kz, sx, sy, sz, ox, oy, oz, inv_x, inv_y, inv_z, res)
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
            kx, ky, kz = keys_after(ox, oy, oz, dx, dy, dz, inv_x, inv_y, inv_z, sx, sy, sz,
                                    kx0, ky0, kz0, t0, res)
            tx, ty, tz = event_times(kx, ky, kz, sx, sy, sz, ox, oy, oz, inv_x, inv_y, inv_z, res)
            continue
        moved, kx, ky, kz, tx, ty, tz = dda_step(kx, ky, kz, tx, ty, tz, sx, sy, sz, ox, oy, oz,
                                                 inv_x, inv_y, inv_z, res, t_stop)
        if not moved:
            return MISS
