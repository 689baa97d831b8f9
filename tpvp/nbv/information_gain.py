"""Geometric information gain of candidate views and the next best view (docs/sensor.md#information-gain).

A view casts one ray per pixel ``(u, v)`` with ``u, v = 0, stride, 2 stride, ...`` (every 4th
pixel for single plants) through the occupancy map; a ray walks the map's voxels until the first
occupied one (or the map's end, or the maximum range). The gain is the number of distinct unknown
voxels that any ray of the view visits (optionally, the expected number seen when unknown voxels
occlude with probability ``1 - unknown_visibility``). Ray directions are those of
:func:`tpvp.sensor.camera.pixel_ray_directions`, bit for bit.

Two exact ways to the same counts:

* the walk (:func:`tpvp.nbv.occupancy.walk`: every voxel of every ray; ``reference=True``, and
  the visibility-weighted gain);
* by voxel (the default for counts). The walk is the DDA of :mod:`tpvp.sensor.raycast`: it does
  the boundary events of the three axes in the order of their closed-form times, ties to the
  lowest axis, none beyond ``t_stop``. So a ray is in voxel ``(a, b, c)`` exactly between the
  last of the events that bring each axis's index to ``a``, ``b``, ``c`` (its entry) and the
  first that takes one away (its exit), and visits it when the entry comes before the exit (in
  the order ``(time, axis)``) and at ``t <= t_stop``: an O(1) test on the same floating-point
  event times. A ray stops at the first occupied voxel it visits (the earliest entry), and an
  unknown voxel counts when some ray visits it before its stop. Only the rays that can pass
  through a voxel are tested: those whose pixel lies in the image bounding box of the voxel's
  projected corners, plus a margin far above rounding (every ray for a voxel at the camera
  plane, none for one behind it). Few voxels are occupied and most unknown ones are settled by
  their first ray, so this costs far less than walking every ray through free space.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from tpvp.errors import ConfigError
from tpvp.nbv.occupancy import (MODE_GAIN, MODE_VISIBILITY, OCCUPIED, TRUE, UNKNOWN, ZERO, OccupancyMap, pixel_ray,
                                walk)
from tpvp.numba_tools import JIT, run_workers
from tpvp.sensor.camera import D435, Intrinsics, look_at_rotations

# A voxel closer than this to the camera plane (m, along the optical axis) may be on any pixel ray;
# one behind it by more than _BEHIND (far above rounding) is on none.
_MIN_DEPTH = 1e-6
_BEHIND = 1e-9
# Pixels added around a voxel's projected bounding box (rounding is ~1e-9 pixel there).
_MARGIN = 0.01


@njit(**JIT)
def _axis_span(a, k0, s, o, inv, res):
    """``(ok, t_in, t_out)``: the events along one axis that bring the ray's index to ``a`` and take
    it away (``-inf`` / ``inf`` when it holds ``a`` from the start / for ever; ``ok`` False when it
    never holds ``a``). The times are the DDA's (``tpvp.sensor.raycast.event_time``) bit for bit."""
    if s > 0:
        if a < k0:
            return False, 0.0, 0.0
        t_in = -np.inf if a == k0 else (a * res - o) * inv  # leaving a - 1: ((a - 1) + 1) res
        return True, t_in, ((a + 1) * res - o) * inv
    if s < 0:
        if a > k0:
            return False, 0.0, 0.0
        t_in = -np.inf if a == k0 else ((a + 1) * res - o) * inv  # leaving a + 1
        return True, t_in, (a * res - o) * inv
    if a != k0:
        return False, 0.0, 0.0
    return True, -np.inf, np.inf


@njit(**JIT)
def _entry(a, b, c, k0x, k0y, k0z, ox, oy, oz, sx, sy, sz, inv_x, inv_y, inv_z, t_stop, res):
    """``(visited, t, axis)``: whether the ray visits voxel ``(a, b, c)`` and its entry event."""
    okx, tix, tox = _axis_span(a, k0x, sx, ox, inv_x, res)
    if not okx:
        return False, 0.0, 0
    oky, tiy, toy = _axis_span(b, k0y, sy, oy, inv_y, res)
    if not oky:
        return False, 0.0, 0
    okz, tiz, toz = _axis_span(c, k0z, sz, oz, inv_z, res)
    if not okz:
        return False, 0.0, 0
    # Latest entry and earliest exit in the DDA's order (time, then axis).
    t_in, ax_in = tix, 0
    if tiy >= t_in:
        t_in, ax_in = tiy, 1
    if tiz >= t_in:
        t_in, ax_in = tiz, 2
    t_out, ax_out = tox, 0
    if toy < t_out:
        t_out, ax_out = toy, 1
    if toz < t_out:
        t_out, ax_out = toz, 2
    visited = (t_in < t_out or (t_in == t_out and ax_in < ax_out)) and t_in <= t_stop
    return visited, t_in, ax_in


@njit(**JIT)
def _footprint(a, b, c, res, ox, oy, oz, rot, fx, fy, cx, cy, stride, r0, r1, c0, c1):
    """Rows and columns ``(ra, rb, ca, cb)`` (inclusive, clipped to ``[r0, r1] x [c0, c1]``) of the
    pixel rays that may pass through voxel ``(a, b, c)``, the ray ``(rm, cm)`` nearest its centre,
    and a ray parameter ``near`` that no ray enters it before. Pixel directions have camera z = 1,
    so a ray's point at ``t`` lies at depth ``t``: a voxel behind the camera plane has no ray
    (empty range); one reaching it may have any (the whole window)."""
    umin, umax, vmin, vmax = np.inf, -np.inf, np.inf, -np.inf
    dmin, dmax = np.inf, -np.inf
    for i in range(8):
        px = (a + (i & 1)) * res - ox
        py = (b + ((i >> 1) & 1)) * res - oy
        pz = (c + ((i >> 2) & 1)) * res - oz
        q0 = rot[0, 0] * px + rot[1, 0] * py + rot[2, 0] * pz
        q1 = rot[0, 1] * px + rot[1, 1] * py + rot[2, 1] * pz
        q2 = rot[0, 2] * px + rot[1, 2] * py + rot[2, 2] * pz
        dmin, dmax = min(dmin, q2), max(dmax, q2)
        if q2 > 0.0:
            u = fx * q0 / q2 + cx
            v = fy * q1 / q2 + cy
            umin, umax = min(umin, u), max(umax, u)
            vmin, vmax = min(vmin, v), max(vmax, v)
    # No ray enters the voxel before this parameter (a ray's parameter is its depth).
    near = dmin - _BEHIND - 1e-12 * abs(dmin)
    if dmax < -_BEHIND:
        return r0, r0 - 1, c0, c0 - 1, r0, c0, near
    if dmin < _MIN_DEPTH:
        return r0, r1, c0, c1, r0, c0, near
    ra = max(r0, np.int64(math.ceil((vmin - _MARGIN) / stride)))
    rb = min(r1, np.int64(math.floor((vmax + _MARGIN) / stride)))
    ca = max(c0, np.int64(math.ceil((umin - _MARGIN) / stride)))
    cb = min(c1, np.int64(math.floor((umax + _MARGIN) / stride)))
    rm = min(rb, max(ra, np.int64(round(0.5 * (vmin + vmax) / stride))))
    cm = min(cb, max(ca, np.int64(round(0.5 * (umin + umax) / stride))))
    return ra, rb, ca, cb, rm, cm, near


@njit(**JIT)
def _argsort(values):
    """Indices that sort ``values`` ascending, ties in any order (a heapsort: np.argsort would cost
    numba a second more to compile)."""
    n = values.shape[0]
    order = np.empty(n, dtype=np.int64)
    for i in range(n):
        order[i] = i
    for start in range(n // 2 - 1, -1, -1):
        _sift_down(values, order, start, n)
    for end in range(n - 1, 0, -1):
        order[0], order[end] = order[end], order[0]
        _sift_down(values, order, ZERO, end)  # ZERO: the signature of the call above (a literal 0 is another)
    return order


@njit(**JIT)
def _sift_down(values, order, root, end):
    """Restore the max-heap ``order[root:end]`` (by ``values``) below ``root``."""
    while True:
        child = 2 * root + 1
        if child >= end:
            return
        if child + 1 < end and values[order[child + 1]] > values[order[child]]:
            child += 1
        if values[order[root]] >= values[order[child]]:
            return
        order[root], order[child] = order[child], order[root]
        root = child


@njit(**JIT, nogil=True)
def _gains_by_voxel(positions, rotations, windows, fx, fy, cx, cy, stride, max_range, occupied,
                    unknown, res, out, worker, workers):
    """Counts of the views (their pixel-ray windows ``[r0, r1, c0, c1]``, see :func:`_window`):
    see the module docstring. ``occupied`` / ``unknown``: keys ``(n, 3)`` of the map's voxels in
    those states. Views ``worker, worker + workers, ...`` (:func:`tpvp.numba_tools.run_workers`;
    neighbouring views cost alike)."""
    nviews = positions.shape[0]
    size = 1
    for v in range(nviews):
        w = windows[v]
        size = max(size, (w[1] - w[0] + 1) * (w[3] - w[2] + 1))
    inv = np.empty((size, 3))
    sgn = np.empty((size, 3), dtype=np.int64)
    t_stop = np.empty(size)
    hit_t = np.empty(size)
    hit_a = np.empty(size, dtype=np.int64)
    for v in range(worker, nviews, workers):
        r0, r1, c0, c1 = windows[v, 0], windows[v, 1], windows[v, 2], windows[v, 3]
        if r0 > r1 or c0 > c1:
            out[v] = 0
            continue
        width = c1 - c0 + 1
        ox, oy, oz = positions[v, 0], positions[v, 1], positions[v, 2]
        rot = rotations[v]
        k0x = np.int64(np.floor(ox / res))  # as tpvp.sensor.raycast.ray_setup
        k0y = np.int64(np.floor(oy / res))
        k0z = np.int64(np.floor(oz / res))
        for r in range(r0, r1 + 1):
            yn = (np.float64(r * stride) - cy) / fy
            for c in range(c0, c1 + 1):
                j = (r - r0) * width + (c - c0)
                dx, dy, dz, ts = pixel_ray(rot, c, stride, yn, cx, fx, max_range)
                t_stop[j] = ts
                for axis, d in ((0, dx), (1, dy), (2, dz)):
                    sgn[j, axis] = 1 if d > 0 else (-1 if d < 0 else 0)
                    inv[j, axis] = 1.0 / d if d != 0 else 0.0
                hit_t[j] = np.inf
                hit_a[j] = 3
        # Each ray's stop: the earliest entry into an occupied voxel. Nearest voxels first, so
        # that farther ones are mostly passed over by the bound below (the order is free).
        dist = np.empty(occupied.shape[0])
        for n in range(occupied.shape[0]):
            ex = (occupied[n, 0] + 0.5) * res - ox
            ey = (occupied[n, 1] + 0.5) * res - oy
            ez = (occupied[n, 2] + 0.5) * res - oz
            dist[n] = ex * ex + ey * ey + ez * ez
        for n in _argsort(dist):
            a, b, c = occupied[n, 0], occupied[n, 1], occupied[n, 2]
            ra, rb, ca, cb, _, _, near = _footprint(a, b, c, res, ox, oy, oz, rot, fx, fy, cx,
                                                    cy, stride, r0, r1, c0, c1)
            for r in range(ra, rb + 1):
                for cc in range(ca, cb + 1):
                    j = (r - r0) * width + (cc - c0)
                    if hit_t[j] < near or t_stop[j] < near:
                        continue  # it stops before reaching this voxel
                    seen, t, ax = _entry(a, b, c, k0x, k0y, k0z, ox, oy, oz, sgn[j, 0],
                                         sgn[j, 1], sgn[j, 2], inv[j, 0], inv[j, 1], inv[j, 2],
                                         t_stop[j], res)
                    if seen and (t < hit_t[j] or (t == hit_t[j] and ax < hit_a[j])):
                        hit_t[j] = t
                        hit_a[j] = ax
        # An unknown voxel counts when a ray visits it before its stop.
        count = 0
        for n in range(unknown.shape[0]):
            a, b, c = unknown[n, 0], unknown[n, 1], unknown[n, 2]
            ra, rb, ca, cb, rm, cm, near = _footprint(a, b, c, res, ox, oy, oz, rot, fx, fy,
                                                      cx, cy, stride, r0, r1, c0, c1)
            if ra > rb or ca > cb:
                continue
            found = False
            for k in range(-1, (rb - ra + 1) * (cb - ca + 1)):
                if k < 0:
                    r, cc = rm, cm  # the central ray first: it settles most voxels
                else:
                    r, cc = ra + k // (cb - ca + 1), ca + k % (cb - ca + 1)
                    if r == rm and cc == cm:
                        continue
                j = (r - r0) * width + (cc - c0)
                if hit_t[j] < near or t_stop[j] < near:
                    continue  # it stops before reaching this voxel
                seen, t, ax = _entry(a, b, c, k0x, k0y, k0z, ox, oy, oz, sgn[j, 0], sgn[j, 1],
                                     sgn[j, 2], inv[j, 0], inv[j, 1], inv[j, 2], t_stop[j], res)
                if seen and (t < hit_t[j] or (t == hit_t[j] and ax < hit_a[j])):
                    found = True
                    break
            if found:
                count += 1
        out[v] = count


@njit(**JIT, nogil=True)
def _gains(positions, rotations, fx, fy, cx, cy, width, height, stride, max_range, state, lo, res,
           visibility, out, worker, workers):
    # The walk: every voxel of every ray, from the map's box entry; views worker, worker +
    # workers, ... (tpvp.numba_tools.run_workers).
    ncols = (width + stride - 1) // stride
    nrows = (height + stride - 1) // stride
    mode = MODE_VISIBILITY if visibility > 0.0 else MODE_GAIN
    tag = visibility if visibility > 0.0 else 1.0
    no_keys = np.zeros(0, dtype=np.int64)
    for v in range(worker, positions.shape[0], workers):
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
                              mode, TRUE, ZERO, ZERO, ZERO, stamp, tag, no_keys)
        out[v] = stamp.sum() if visibility > 0.0 else count


def _window(positions, rotations, box, res, intrinsics: Intrinsics, stride: int) -> np.ndarray:
    """Per view, the pixel rays ``[r0, r1, c0, c1]`` (inclusive) that may reach the key box
    ``box`` (``[lo, hi)``): the bounding box of its projected corners, or every ray when the box
    reaches the camera plane (empty when it lies behind)."""
    k = intrinsics
    corners = np.array([[box[3 * (i >> a & 1) + a] for a in range(3)] for i in range(8)],
                       dtype=np.float64) * res
    rel = corners[None, :, :] - positions[:, None, :]  # (V, 8, 3)
    q = np.einsum("vci,vij->vcj", rel, rotations)  # camera frame: R^T (p - o)
    near = q[:, :, 2].min(axis=1) < _MIN_DEPTH
    behind = q[:, :, 2].max(axis=1) < -_BEHIND
    depth = np.where(near[:, None], 1.0, q[:, :, 2])
    u = k.fx * q[:, :, 0] / depth + k.cx
    v = k.fy * q[:, :, 1] / depth + k.cy
    ncols = (int(k.width) + stride - 1) // stride
    nrows = (int(k.height) + stride - 1) // stride
    window = np.stack([
        np.maximum(0, np.ceil((v.min(axis=1) - 2 * _MARGIN) / stride)),
        np.minimum(nrows - 1, np.floor((v.max(axis=1) + 2 * _MARGIN) / stride)),
        np.maximum(0, np.ceil((u.min(axis=1) - 2 * _MARGIN) / stride)),
        np.minimum(ncols - 1, np.floor((u.max(axis=1) + 2 * _MARGIN) / stride)),
    ], axis=1).astype(np.int64)
    window[near] = [0, nrows - 1, 0, ncols - 1]
    window[behind] = [0, -1, 0, -1]
    return np.ascontiguousarray(window)


def information_gain(occupancy: OccupancyMap, positions, look_ats, stride: int = 4,
                     max_range: float = 1.0, intrinsics: Intrinsics = D435,
                     unknown_visibility: float | None = None, reference: bool = False) -> np.ndarray:
    """Gain ``(V,)`` of each candidate view (position + look-at) on ``occupancy``.

    Default: ``int64`` counts of distinct unknown voxels visited. With ``unknown_visibility``
    ``p`` in (0, 1), the probability that an unknown voxel lets a ray through, the expected
    number of unknown voxels seen (``float64``): a ray sees its ``n``-th unknown voxel (from 0)
    with probability ``p ** n``, and a voxel counts with its largest probability over the view's
    rays. ``reference=True`` walks every ray voxel by voxel (slow; the same counts, for tests and
    benchmarks).
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
    if not len(positions):
        return out
    k = intrinsics
    # Writable C-ordered copies: numba compiles a kernel once per argument type, and read-only
    # arrays (a view space's positions) are a type of their own.
    positions = np.array(positions, order="C")
    rotations = np.array(rotations, order="C")
    # The map's state is read-only and the walk is typed for writable arrays; the copy (tens of
    # kB) is not written to.
    state = np.array(occupancy.state, order="C")
    lo, res, stride = occupancy.origin_key, occupancy.resolution, int(stride)
    if reference or visibility:
        run_workers(_gains, len(positions), positions, rotations, k.fx, k.fy, k.cx, k.cy, int(k.width),
                    int(k.height), stride, float(max_range), state, lo, res, visibility, out)
        return out
    unknown = np.argwhere(state == UNKNOWN)
    if not len(unknown):
        return out  # nothing left to see: every gain is 0
    occupied = np.argwhere(state == OCCUPIED)
    both = np.concatenate([unknown, occupied])
    box = np.r_[both.min(axis=0), both.max(axis=0) + 1] + np.r_[lo, lo]
    # Keys in C order (argwhere's are F-ordered, or C for a single row: one kernel type for all).
    run_workers(_gains_by_voxel, len(positions), positions, rotations,
                _window(positions, rotations, box, res, k, stride), k.fx, k.fy, k.cx, k.cy, stride,
                float(max_range), np.ascontiguousarray(occupied + lo), np.ascontiguousarray(unknown + lo),
                res, out)
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
