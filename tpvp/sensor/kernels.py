"""Numba kernels of the two measurement models, one view or many views at once.

* ``reference`` (the authors' simulator, docs/sensor.md#reference-model): every occupied voxel whose centre lies in front
  of the camera and projects inside the image spawns one ray toward its centre; the first occupied
  voxel along it is observed.
* ``pixel`` (a real depth camera): one ray per pixel (optional stride). Computed as a z-buffer over
  the exposed, camera-facing voxel faces: a pixel ray first enters an occupied voxel through such a
  face, so the nearest face it crosses is the first occupied voxel of the DDA. Each candidate pixel
  is tested exactly (ray-plane intersection inside the face square), the projected face only bounds
  which pixels to test.

Single views run serially; batches of views are split over threads (:mod:`tpvp.numba_tools`), because a
thread pool stalls on sub-millisecond work when the other core is busy.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from tpvp.numba_tools import JIT
from tpvp.sensor.raycast import MISS, cast_ray


@njit(**JIT)
def _segment_exit(pos, rx, ry, rz, box):
    """Parameter where the segment ``pos + t r`` (``t`` in [0, 1]) leaves the box ``(lo, hi)``.

    Negative when the segment misses the box.
    """
    t0 = 0.0
    t1 = 1.0
    for a in range(3):
        d = rx if a == 0 else (ry if a == 1 else rz)
        if d == 0.0:
            if pos[a] < box[a] or pos[a] > box[a + 3]:
                return -1.0
        else:
            ta = (box[a] - pos[a]) / d
            tb = (box[a + 3] - pos[a]) / d
            if ta > tb:
                ta, tb = tb, ta
            t0 = max(t0, ta)
            t1 = min(t1, tb)
            if t0 > t1:
                return -1.0
    return t1


@njit(**JIT)
def reference_view(pos, rot, fx, fy, cx, cy, width, height, centres, index, clearance, lo, res,
                   max_range_sq, countable, countable_box, first_hit):
    """Fill ``first_hit[i]`` with the voxel seen along the ray toward centre ``i`` (MISS if none).

    Only the part of each ray inside ``countable_box`` (the box around every countable voxel, padded
    by one voxel) can end on a voxel that counts, so rays are cut where their segment (camera to
    target centre) leaves that box, and not cast at all when they miss it: the table then costs
    almost nothing. Other voxels still block. Returns the number of rays cast.
    """
    rays = 0
    for i in range(centres.shape[0]):
        first_hit[i] = MISS
        rx = centres[i, 0] - pos[0]
        ry = centres[i, 1] - pos[1]
        rz = centres[i, 2] - pos[2]
        zc = rot[0, 2] * rx + rot[1, 2] * ry + rot[2, 2] * rz
        if zc <= 0.0:
            continue
        xc = rot[0, 0] * rx + rot[1, 0] * ry + rot[2, 0] * rz
        u = fx * xc / zc + cx
        if u < 0.0 or u > width:
            continue
        yc = rot[0, 1] * rx + rot[1, 1] * ry + rot[2, 1] * rz
        v = fy * yc / zc + cy
        if v < 0.0 or v > height:
            continue
        t_stop = _segment_exit(pos, rx, ry, rz, countable_box)
        if t_stop < 0.0:
            continue
        rays += 1
        first_hit[i] = cast_ray(pos[0], pos[1], pos[2], rx, ry, rz, index, clearance,
                                lo[0], lo[1], lo[2], res, max_range_sq, t_stop)
    return rays


@njit(**JIT)
def countable_hit_ids(first_hit, countable):
    """Sorted distinct countable voxel ids in ``first_hit`` (a marker array, no sort)."""
    seen = np.zeros(countable.shape[0], dtype=np.bool_)
    _mark_hits(first_hit, countable, seen)
    return np.flatnonzero(seen)


@njit(**JIT)
def _mark_hits(first_hit, countable, seen):
    for i in range(first_hit.shape[0]):
        h = first_hit[i]
        if h >= 0 and countable[h]:
            seen[h] = True


@njit(**JIT, nogil=True)
def reference_views(positions, rotations, fx, fy, cx, cy, width, height, centres, index, clearance,
                    lo, res, max_range_sq, countable, countable_box, seen, worker, workers):
    """``seen[v, id] = True`` for every countable voxel observed from view ``v``, for views ``worker,
    worker + workers, ...`` (:func:`tpvp.numba_tools.run_workers`)."""
    first_hit = np.empty(centres.shape[0], dtype=np.int64)
    for v in range(worker, positions.shape[0], workers):
        reference_view(positions[v], rotations[v], fx, fy, cx, cy, width, height, centres, index,
                       clearance, lo, res, max_range_sq, countable, countable_box, first_hit)
        _mark_hits(first_hit, countable, seen[v])


# --------------------------------------------------------------------------------------------
# pixel model


@njit(**JIT)
def exposed_faces(keys, index, lo):
    """6-bit mask per voxel: bit ``2*axis`` = face on the low side exposed, ``2*axis+1`` = high side."""
    n0, n1, n2 = index.shape
    out = np.zeros(keys.shape[0], dtype=np.uint8)
    for i in range(keys.shape[0]):
        base = (keys[i, 0] - lo[0], keys[i, 1] - lo[1], keys[i, 2] - lo[2])
        mask = 0
        for axis in range(3):
            for side in range(2):
                nb0, nb1, nb2 = base
                delta = 1 if side == 1 else -1
                if axis == 0:
                    nb0 += delta
                elif axis == 1:
                    nb1 += delta
                else:
                    nb2 += delta
                empty = True
                if 0 <= nb0 < n0 and 0 <= nb1 < n1 and 0 <= nb2 < n2:
                    empty = index[nb0, nb1, nb2] < 0
                if empty:
                    mask |= 1 << (2 * axis + side)
        out[i] = mask
    return out


_NEAR = 1e-6  # near plane (m) for clipping geometry that straddles the camera plane
_CUBE_EDGES = np.array([[0, 1], [2, 3], [4, 5], [6, 7], [0, 2], [1, 3], [4, 6], [5, 7],
                        [0, 4], [1, 5], [2, 6], [3, 7]], dtype=np.int64)
_QUAD_EDGES = np.array([[0, 1], [1, 3], [3, 2], [2, 0]], dtype=np.int64)


@njit(**JIT)
def _clipped_bounds(cam, edges, fx, fy, cx, cy):
    """Image bounds ``(umin, umax, vmin, vmax)`` of a convex solid/polygon given by its corners in
    camera coordinates, clipped to the half-space in front of the camera (empty when all behind)."""
    umin = np.inf
    umax = -np.inf
    vmin = np.inf
    vmax = -np.inf
    clipped = False
    for q in range(cam.shape[0]):
        if cam[q, 2] > _NEAR:
            u = fx * cam[q, 0] / cam[q, 2] + cx
            v = fy * cam[q, 1] / cam[q, 2] + cy
            umin, umax, vmin, vmax = min(umin, u), max(umax, u), min(vmin, v), max(vmax, v)
        else:
            clipped = True
    if not clipped:
        return umin, umax, vmin, vmax
    for e in range(edges.shape[0]):
        a, b = edges[e, 0], edges[e, 1]
        za, zb = cam[a, 2], cam[b, 2]
        if (za > _NEAR) != (zb > _NEAR):
            w = (_NEAR - za) / (zb - za)
            x = cam[a, 0] + w * (cam[b, 0] - cam[a, 0])
            y = cam[a, 1] + w * (cam[b, 1] - cam[a, 1])
            u = fx * x / _NEAR + cx
            v = fy * y / _NEAR + cy
            umin, umax, vmin, vmax = min(umin, u), max(umax, u), min(vmin, v), max(vmax, v)
    return umin, umax, vmin, vmax


@njit(**JIT)
def pixel_window(pos, rot, fx, fy, cx, cy, width, height, stride, centres, res):
    """Strided pixel rows/columns ``(row0, row1, col0, col1)`` (inclusive) that any voxel can cover.

    Bounds each voxel by its circumscribed sphere; a voxel that straddles the camera plane is
    bounded exactly by its cube clipped to the front half-space.
    """
    rows = (height + stride - 1) // stride
    cols = (width + stride - 1) // stride
    radius = 0.8660254037844387 * res
    umin = np.inf
    umax = -np.inf
    vmin = np.inf
    vmax = -np.inf
    for i in range(centres.shape[0]):
        rx = centres[i, 0] - pos[0]
        ry = centres[i, 1] - pos[1]
        rz = centres[i, 2] - pos[2]
        zc = rot[0, 2] * rx + rot[1, 2] * ry + rot[2, 2] * rz
        if zc <= -radius:
            continue
        if zc <= radius + 1e-9:
            cam = np.empty((8, 3))
            for q in range(8):
                wx = centres[i, 0] - 0.5 * res + res * (q & 1) - pos[0]
                wy = centres[i, 1] - 0.5 * res + res * ((q >> 1) & 1) - pos[1]
                wz = centres[i, 2] - 0.5 * res + res * ((q >> 2) & 1) - pos[2]
                for a in range(3):
                    cam[q, a] = rot[0, a] * wx + rot[1, a] * wy + rot[2, a] * wz
            a0, a1, b0, b1 = _clipped_bounds(cam, _CUBE_EDGES, fx, fy, cx, cy)
            umin, umax, vmin, vmax = min(umin, a0), max(umax, a1), min(vmin, b0), max(vmax, b1)
            continue
        u = fx * (rot[0, 0] * rx + rot[1, 0] * ry + rot[2, 0] * rz) / zc + cx
        v = fy * (rot[0, 1] * rx + rot[1, 1] * ry + rot[2, 1] * rz) / zc + cy
        # The sphere's projection: its centre's projection +- a radius scaled by the nearest depth,
        # inflated for the off-axis stretch (a generous factor; only the window size depends on it).
        slack = 2.0 * radius * max(fx, fy) / (zc - radius) * (1.0 + (abs(u - cx) + abs(v - cy)) / fx)
        umin = min(umin, u - slack)
        umax = max(umax, u + slack)
        vmin = min(vmin, v - slack)
        vmax = max(vmax, v + slack)
    if umin > umax:
        return 0, -1, 0, -1
    return _pixel_range(umin, umax, vmin, vmax, stride, 2.0, rows, cols)


@njit(**JIT)
def _pixel_range(umin, umax, vmin, vmax, stride, slack, rows, cols):
    """Strided pixel indices inside the image bounds widened by ``slack`` pixels, clamped to the
    image."""
    # Clamp in float first: clipped geometry can project to astronomically large coordinates.
    umin = min(max(umin - slack, -1.0), cols * stride + 1.0)
    umax = min(max(umax + slack, -1.0), cols * stride + 1.0)
    vmin = min(max(vmin - slack, -1.0), rows * stride + 1.0)
    vmax = min(max(vmax + slack, -1.0), rows * stride + 1.0)
    c0 = max(0, np.int64(np.ceil(umin / stride)))
    c1 = min(cols - 1, np.int64(np.floor(umax / stride)))
    r0 = max(0, np.int64(np.ceil(vmin / stride)))
    r1 = min(rows - 1, np.int64(np.floor(vmax / stride)))
    return r0, r1, c0, c1


@njit(**JIT)
def pixel_view(pos, rot, fx, fy, cx, cy, stride, keys, exposed, res, row0, col0, depth, hit):
    """Z-buffer of exposed camera-facing faces on a window of the strided pixel grid.

    ``depth``/``hit`` cover strided pixel rows ``row0 ..`` and columns ``col0 ..`` (see
    :func:`pixel_window`); on return ``hit`` holds the id of the first occupied voxel of each pixel
    ray (MISS if none) and ``depth`` its camera-z depth. Range is not applied here.
    """
    rows, cols = hit.shape
    for r in range(rows):
        for c in range(cols):
            depth[r, c] = np.inf
            hit[r, c] = MISS
    cam = np.empty((4, 3))
    for i in range(keys.shape[0]):
        mask = exposed[i]
        if mask == 0:
            continue
        for a in range(3):
            low = keys[i, a] * res
            high = (keys[i, a] + 1) * res
            if pos[a] > high:
                plane = high
                bit = 2 * a + 1
            elif pos[a] < low:
                plane = low
                bit = 2 * a
            else:
                continue  # the camera is level with this pair of faces: neither faces it
            if (mask >> bit) & 1 == 0:
                continue
            b = (a + 1) % 3
            e = (a + 2) % 3
            b_lo = keys[i, b] * res
            b_hi = (keys[i, b] + 1) * res
            e_lo = keys[i, e] * res
            e_hi = (keys[i, e] + 1) * res
            # Pixel bounding box of the projected face, clipped in front of the camera (one pixel
            # of slack against rounding); faces entirely behind the camera are skipped.
            # Corner (b_lo, e_lo) in camera coordinates, then step along the face's two axes.
            w0 = plane - pos[a]
            w1 = b_lo - pos[b]
            w2 = e_lo - pos[e]
            front = True
            umin = np.inf
            umax = -np.inf
            vmin = np.inf
            vmax = -np.inf
            for q in range(4):
                sb = res if (q & 1) else 0.0
                se = res if (q & 2) else 0.0
                for k in range(3):
                    cam[q, k] = rot[a, k] * w0 + rot[b, k] * (w1 + sb) + rot[e, k] * (w2 + se)
                if cam[q, 2] <= _NEAR:
                    front = False
                else:
                    u = fx * cam[q, 0] / cam[q, 2] + cx
                    v = fy * cam[q, 1] / cam[q, 2] + cy
                    umin, umax, vmin, vmax = min(umin, u), max(umax, u), min(vmin, v), max(vmax, v)
            if not front:  # rare: the face reaches behind the camera plane, clip it
                umin, umax, vmin, vmax = _clipped_bounds(cam, _QUAD_EDGES, fx, fy, cx, cy)
            if umin > umax:
                continue
            r0, r1, c0, c1 = _pixel_range(umin, umax, vmin, vmax, stride, 1.0, row0 + rows, col0 + cols)
            r0 = max(r0 - row0, 0)
            r1 -= row0
            c0 = max(c0 - col0, 0)
            c1 -= col0
            for r in range(r0, r1 + 1):
                yn = ((r + row0) * stride - cy) / fy
                for c in range(c0, c1 + 1):
                    xn = ((c + col0) * stride - cx) / fx
                    d0 = rot[0, 0] * xn + rot[0, 1] * yn + rot[0, 2]
                    d1 = rot[1, 0] * xn + rot[1, 1] * yn + rot[1, 2]
                    d2 = rot[2, 0] * xn + rot[2, 1] * yn + rot[2, 2]
                    da = d0 if a == 0 else (d1 if a == 1 else d2)
                    if da == 0.0:
                        continue
                    t = (plane - pos[a]) / da
                    if t <= 0.0 or t >= depth[r, c]:
                        continue
                    db = d0 if b == 0 else (d1 if b == 1 else d2)
                    de = d0 if e == 0 else (d1 if e == 1 else d2)
                    pb = pos[b] + t * db
                    if pb < b_lo or pb > b_hi:
                        continue
                    pe = pos[e] + t * de
                    if pe < e_lo or pe > e_hi:
                        continue
                    depth[r, c] = t
                    hit[r, c] = i


@njit(**JIT)
def _mark_pixel_hits(hit, pos, centres, countable, max_range_sq, seen):
    rows, cols = hit.shape
    for r in range(rows):
        for c in range(cols):
            h = hit[r, c]
            if h >= 0 and countable[h] and not seen[h]:
                dx = centres[h, 0] - pos[0]
                dy = centres[h, 1] - pos[1]
                dz = centres[h, 2] - pos[2]
                if dx * dx + dy * dy + dz * dz <= max_range_sq:
                    seen[h] = True


@njit(**JIT)
def pixel_view_seen(pos, rot, fx, fy, cx, cy, width, height, stride, keys, exposed, res, centres,
                    max_range_sq, countable, seen, depth_buffer, hit_buffer):
    """Mark in ``seen`` the countable voxels (within range) that any pixel ray of the view hits.

    ``depth_buffer``/``hit_buffer`` are scratch images of at least the strided image size, reused
    across views (allocating them per view costs more than the z-buffer itself).
    """
    r0, r1, c0, c1 = pixel_window(pos, rot, fx, fy, cx, cy, width, height, stride, centres, res)
    if r1 < r0 or c1 < c0:
        return
    depth = depth_buffer[:r1 - r0 + 1, :c1 - c0 + 1]
    hit = hit_buffer[:r1 - r0 + 1, :c1 - c0 + 1]
    pixel_view(pos, rot, fx, fy, cx, cy, stride, keys, exposed, res, r0, c0, depth, hit)
    _mark_pixel_hits(hit, pos, centres, countable, max_range_sq, seen)


@njit(**JIT, nogil=True)
def pixel_views(positions, rotations, fx, fy, cx, cy, width, height, stride, keys, exposed, res,
                centres, max_range_sq, countable, seen, worker, workers):
    """``seen[v, id] = True`` for every countable voxel seen by a pixel of view ``v``, for the
    ``worker``-th of ``workers`` contiguous blocks of views (:func:`tpvp.numba_tools.run_workers`; one
    scratch image per block)."""
    rows = (height + stride - 1) // stride
    cols = (width + stride - 1) // stride
    n = positions.shape[0]
    depth = np.empty((rows, cols))
    hit = np.empty((rows, cols), dtype=np.int64)
    for v in range(worker * n // workers, (worker + 1) * n // workers):
        pixel_view_seen(positions[v], rotations[v], fx, fy, cx, cy, width, height, stride, keys,
                        exposed, res, centres, max_range_sq, countable, seen[v], depth, hit)
