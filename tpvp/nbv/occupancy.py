"""Occupancy map of what has been observed (NBV baselines and the warm-up, docs/single_plant.md#occupancy-map).

The map is a dense three-state grid (unknown / free / occupied) over the cube ``centre +-
predicted_size`` (plus padding), with ``predicted_size = 17/16 * max |observed point - centre|`` and
voxel ``2 * predicted_size / 32``. Voxel keys follow :mod:`tpvp.scene.voxels` (world aligned,
``floor(x / res)``), as in OctoMap.

Integrating a view marks the voxels of its observed points occupied and carves free every voxel
that the ray from the camera to an observed voxel's centre traverses before that voxel. Given the
view's look-at, it also carves free space along the view's own pixel rays (every ``stride``-th pixel,
as in the information gain): a depth camera reports where it saw nothing, so each pixel ray marks
free every voxel it traverses up to the first voxel holding one of the view's own observed points
(its return), the maximum range, or the map's end. Free never overrides occupied, and a view's
carving depends only on its own observation, so the map depends on the set of observations, not on
their order.

Rays walk the exact DDA of :mod:`tpvp.sensor.raycast` (same closed-form event times, ties to the
lowest axis). A ray that starts outside the map may jump to where it enters the map's box; the jump
reproduces the state of the plain step-by-step walk exactly (see ``tpvp.sensor.raycast.key_after``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numba import njit

from tpvp.errors import ConfigError, PointCloudError
from tpvp.nbv.config import OccupancyMapConfig
from tpvp.numba_tools import JIT
from tpvp.scene import voxels
from tpvp.sensor.camera import D435, Intrinsics, look_at_rotation
from tpvp.sensor.raycast import dda_step, encode_key_jit, event_times, keys_after, ray_setup, slab

UNKNOWN = np.uint8(0)
FREE = np.uint8(1)
OCCUPIED = np.uint8(2)

_MAX_CELLS = 50_000_000


def _as_points(points, name: str) -> np.ndarray:
    arr = np.asarray(points, dtype=np.float64)
    if arr.size == 0:
        return np.zeros((0, 3))
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise PointCloudError(f"{name} must be an (n, 3) array, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise PointCloudError(f"{name} contains NaN or infinite coordinates")
    return arr


def _as_position(position, name: str) -> np.ndarray:
    arr = np.array(position, dtype=np.float64)  # a writable copy: one kernel type for all callers
    if arr.size != 3 or not np.all(np.isfinite(arr)):
        raise ConfigError(f"{name} must be 3 finite coordinates, got {np.asarray(position).tolist()!r}")
    return arr.reshape(3)


def observed_radius(centre, points, name: str = "observed points") -> float:
    """Largest distance from ``centre`` to an observed point (0 for none): the map is sized on
    the largest over all views (:meth:`OccupancyMap.from_observations`)."""
    points = _as_points(points, name)
    if not len(points):
        return 0.0
    return float(np.sqrt(((points - _as_position(centre, "map centre")) ** 2).sum(axis=1)).max())


@dataclass(frozen=True, eq=False)
class OccupancyMap:
    """Dense unknown / free / occupied grid; immutable (``integrate`` returns a new map)."""

    centre: np.ndarray  # (3,) object centre
    predicted_size: float  # half-side of the mapped cube, m
    resolution: float  # voxel size, m
    origin_key: np.ndarray  # (3,) int64 key of dense cell [0, 0, 0]
    state: np.ndarray  # (X, Y, Z) uint8: UNKNOWN, FREE or OCCUPIED (read-only)

    @classmethod
    def empty(cls, centre, predicted_size: float,
              config: OccupancyMapConfig = OccupancyMapConfig()) -> OccupancyMap:
        """All-unknown map of the cube ``centre +- predicted_size``."""
        centre = _as_position(centre, "map centre")
        if not (np.isfinite(predicted_size) and predicted_size > 0):
            raise ConfigError(f"predicted_size must be > 0 m, got {predicted_size!r}")
        res = (2.0 * float(predicted_size) / int(config.voxels_across) if config.resolution is None
               else float(config.resolution))
        pad = int(config.padding)
        lo = voxels.voxel_keys(centre - predicted_size, res)[0] - pad
        hi = voxels.voxel_keys(centre + predicted_size, res)[0] + pad
        shape = hi - lo + 1
        if int(np.prod(shape)) > _MAX_CELLS:
            raise ConfigError(f"occupancy map of {shape.tolist()} voxels is too large")
        state = np.zeros(tuple(shape), dtype=np.uint8)
        state.setflags(write=False)
        return cls(centre=centre, predicted_size=float(predicted_size), resolution=res,
                   origin_key=lo.astype(np.int64), state=state)

    @classmethod
    def from_observations(cls, centre, view_positions, observed_points_per_view,
                          config: OccupancyMapConfig = OccupancyMapConfig(), look_ats=None,
                          **carving) -> OccupancyMap:
        """Map sized on all observed points (docs/single_plant.md#occupancy-map), then every view integrated.

        ``look_ats`` (one ``(3,)`` point for all views, or ``(V, 3)``) turns on pixel-ray carving
        (see :meth:`integrate`, which receives ``carving``: ``stride``, ``max_range``,
        ``intrinsics``); ``None`` carves along the rays to observed points only.
        """
        centre = _as_position(centre, "map centre")
        views = [_as_position(p, f"view position {i}") for i, p in enumerate(view_positions)]
        clouds = [_as_points(p, f"observed points of view {i}")
                  for i, p in enumerate(observed_points_per_view)]
        if len(views) != len(clouds):
            raise ConfigError(f"{len(views)} view positions but {len(clouds)} observed clouds")
        if look_ats is None:
            targets = [None] * len(views)
        else:
            arr = np.asarray(look_ats, dtype=np.float64)
            if arr.size == 3:
                arr = np.broadcast_to(arr.reshape(1, 3), (len(views), 3))
            if arr.shape != (len(views), 3):
                raise ConfigError(f"look-ats of shape {np.shape(look_ats)} do not match "
                                  f"{len(views)} view positions")
            targets = [_as_position(t, f"look-at {i}") for i, t in enumerate(arr)]
        if sum(len(c) for c in clouds) == 0:
            raise PointCloudError(f"no observed points: none of the {len(views)} views saw the plant, so the "
                                  f"occupancy map cannot be sized; are the views within the sensor's range of it?")
        radius = max(observed_radius(centre, c) for c in clouds)
        if radius <= 0:
            raise PointCloudError("all observed points coincide with the map centre")
        occupancy = cls.empty(centre, config.size_factor * radius, config)
        for position, cloud, target in zip(views, clouds, targets):
            occupancy = occupancy.integrate(position, cloud, target, **carving)
        return occupancy

    def integrate(self, view_position, points, look_at=None, stride: int = 4,
                  max_range: float = 1.0, intrinsics: Intrinsics = D435) -> OccupancyMap:
        """New map with one view's observed points (occupied) and free space (carved) added.

        Free space: the rays from the camera to the observed voxels' centres and, when ``look_at``
        is given, the view's pixel rays (pixels ``0, stride, 2 stride, ...`` of ``intrinsics``,
        directions of :func:`tpvp.sensor.camera.pixel_ray_directions`), each up to the first voxel
        holding one of this view's points (excluded), ``max_range`` m, or the map's end. A pixel
        ray that crosses a voxel occupied by another view only, without a return of its own, saw
        through it. Points outside the map are not stored, but they stop pixel rays, and the
        in-map part of their rays is carved.
        """
        position = _as_position(view_position, "view position")
        points = _as_points(points, "observed points")
        if look_at is not None:
            if int(stride) != stride or int(stride) < 1:
                raise ConfigError(f"pixel stride must be a positive integer, got {stride!r}")
            if not (max_range > 0):
                raise ConfigError(f"max_range must be > 0 m, got {max_range!r}")
            rotation = look_at_rotation(position, _as_position(look_at, "look-at"))
        elif len(points) == 0:
            return self  # rays are cast only to observed points: nothing to add
        # One ray per map voxel: points in the same voxel would carve (almost) the same path.
        keys = voxels.voxelise(points, self.resolution) if len(points) else np.zeros((0, 3), np.int64)
        state = self.state.copy()
        local = keys - self.origin_key
        inside = np.all((local >= 0) & (local < state.shape), axis=1)
        state[tuple(local[inside].T)] = OCCUPIED
        _carve(position, np.ascontiguousarray(keys), state, self.origin_key, self.resolution)
        if look_at is not None:
            own = np.zeros(state.size)  # 1 at this view's returns, flat
            own[np.ravel_multi_index(tuple(local[inside].T), state.shape)] = 1.0
            # Returns outside the map stop pixel rays only before the rays reach the map (it is
            # convex), so only those within range of the camera matter.
            outer = keys[~inside]
            reach = max_range + 2.0 * np.sqrt(3.0) * self.resolution
            outer = outer[((voxels.key_centres(outer, self.resolution) - position) ** 2).sum(axis=1)
                          <= reach * reach]
            k = intrinsics
            _carve_pixels(position, rotation, k.fx, k.fy, k.cx, k.cy, int(k.width), int(k.height),
                          int(stride), float(max_range), state, self.origin_key, self.resolution,
                          own, np.unique(voxels.encode_keys(outer)))
        state.setflags(write=False)
        return replace(self, state=state)

    @property
    def shape(self) -> tuple:
        return self.state.shape

    def count(self, which) -> int:
        """Number of voxels in state ``which`` (UNKNOWN, FREE or OCCUPIED)."""
        return int(np.count_nonzero(self.state == which))

    def keys(self, which) -> np.ndarray:
        """Keys ``(n, 3)`` of the voxels in state ``which``."""
        return np.argwhere(self.state == which).astype(np.int64) + self.origin_key

    def state_at(self, points) -> np.ndarray:
        """State of the voxel of each point; points outside the map read as UNKNOWN."""
        local = voxels.voxel_keys(points, self.resolution) - self.origin_key
        inside = np.all((local >= 0) & (local < self.state.shape), axis=1)
        out = np.full(len(local), UNKNOWN, dtype=np.uint8)
        out[inside] = self.state[tuple(local[inside].T)]
        return out


# Modes of walk, and the constants its callers pass: numpy scalars, because numba types a Python
# constant argument as a literal and compiles walk once per literal; with these every kernel calls
# the one compiled walk.
MODE_GAIN = np.int64(0)
MODE_CARVE = np.int64(1)
MODE_FREESPACE = np.int64(2)
MODE_VISIBILITY = np.int64(3)
ZERO = np.int64(0)
TRUE = np.bool_(True)
FALSE = np.bool_(False)


@njit(**JIT)
def pixel_ray(rot, c, stride, yn, cx, fx, max_range):
    """World direction of pixel column ``c`` on a row with normalised ``yn`` (the element-wise
    expression of ``pixel_ray_directions``, bit for bit) and the ray parameter at ``max_range``."""
    xn = (np.float64(c * stride) - cx) / fx
    dx = rot[0, 0] * xn + rot[0, 1] * yn + rot[0, 2]
    dy = rot[1, 0] * xn + rot[1, 1] * yn + rot[1, 2]
    dz = rot[2, 0] * xn + rot[2, 1] * yn + rot[2, 2]
    return dx, dy, dz, max_range / math.sqrt(dx * dx + dy * dy + dz * dz)


@njit(**JIT)
def _contains(values, value):
    """Whether the sorted ``values`` hold ``value`` (a binary search: np.searchsorted would cost
    numba half a second more to compile)."""
    lo, hi = 0, values.size
    while lo < hi:
        mid = (lo + hi) // 2
        if values[mid] < value:
            lo = mid + 1
        else:
            hi = mid
    return lo < values.size and values[lo] == value


@njit(**JIT)
def walk(ox, oy, oz, dx, dy, dz, t_stop, state, lo0, lo1, lo2, res, mode, skip,
         ex, ey, ez, stamp, tag, outer):
    """Walk ray ``o + t d`` through the map's voxels (never entering one beyond ``t_stop``).

    ``MODE_GAIN``: stop at the first occupied voxel; return how many unknown voxels were visited
    whose ``stamp`` was not yet ``tag`` (and stamp them). ``MODE_CARVE``: stop on reaching voxel
    ``(ex, ey, ez)``; mark every unknown voxel visited before it free; return 0.
    ``MODE_FREESPACE``: stop on reaching a voxel whose ``stamp`` is ``tag`` (in the map) or whose
    code (:func:`tpvp.scene.voxels.encode_key`) is in the sorted ``outer`` (out of it); mark every
    unknown voxel visited before it free.
    ``MODE_VISIBILITY``: as ``MODE_GAIN``, but raise ``stamp`` of the ``n``-th unknown
    voxel visited (from 0) to at least ``tag ** n``; return 0.
    ``skip`` jumps to the map's box first (exact, but it would also skip a carving end voxel
    lying before the box, so carving walks from the camera). The stepping is the sensor's DDA
    (:mod:`tpvp.sensor.raycast`): same start, entry jump and steps.
    """
    n0, n1, n2 = state.shape
    sx, sy, sz, inv_x, inv_y, inv_z, kx, ky, kz = ray_setup(ox, oy, oz, dx, dy, dz, res)
    if skip:
        # The map's box exactly (its border voxels may be unknown, unlike the sensor's padding).
        a0, b0 = slab(ox, dx, inv_x, lo0 * res, (lo0 + n0) * res, lo0 <= kx < lo0 + n0)
        a1, b1 = slab(oy, dy, inv_y, lo1 * res, (lo1 + n1) * res, lo1 <= ky < lo1 + n1)
        a2, b2 = slab(oz, dz, inv_z, lo2 * res, (lo2 + n2) * res, lo2 <= kz < lo2 + n2)
        t_enter = max(0.0, max(a0, max(a1, a2)))
        t_exit = min(b0, min(b1, b2))
        if t_enter > t_exit or t_enter > t_stop:
            return 0
        if t_enter > 0.0:
            # State after every event with t < t_enter: the voxel just before the box.
            kx, ky, kz = keys_after(ox, oy, oz, dx, dy, dz, inv_x, inv_y, inv_z, sx, sy, sz,
                                    kx, ky, kz, t_enter, res)
    tx, ty, tz = event_times(kx, ky, kz, sx, sy, sz, ox, oy, oz, inv_x, inv_y, inv_z, res)
    count = 0
    weight = 1.0
    while True:
        if mode == MODE_CARVE and kx == ex and ky == ey and kz == ez:
            return 0
        ix, iy, iz = kx - lo0, ky - lo1, kz - lo2
        if 0 <= ix < n0 and 0 <= iy < n1 and 0 <= iz < n2:
            s = state[ix, iy, iz]
            if mode == MODE_CARVE:
                if s == UNKNOWN:
                    state[ix, iy, iz] = FREE
            elif mode == MODE_FREESPACE:
                if stamp[(ix * n1 + iy) * n2 + iz] == tag:
                    return 0
                if s == UNKNOWN:
                    state[ix, iy, iz] = FREE
            else:
                if s == OCCUPIED:
                    return count
                if s == UNKNOWN:
                    flat = (ix * n1 + iy) * n2 + iz
                    if mode == MODE_VISIBILITY:
                        stamp[flat] = max(stamp[flat], weight)
                        weight *= tag
                    elif stamp[flat] != tag:
                        stamp[flat] = tag
                        count += 1
        elif ((ix < 0 and sx <= 0) or (ix >= n0 and sx >= 0) or (iy < 0 and sy <= 0)
              or (iy >= n1 and sy >= 0) or (iz < 0 and sz <= 0) or (iz >= n2 and sz >= 0)):
            return count  # outside and not approaching the (convex) box: it never comes back
        elif mode == MODE_FREESPACE and outer.size > 0:
            if _contains(outer, encode_key_jit(kx, ky, kz)):
                return 0
        moved, kx, ky, kz, tx, ty, tz = dda_step(kx, ky, kz, tx, ty, tz, sx, sy, sz, ox, oy, oz,
                                                 inv_x, inv_y, inv_z, res, t_stop)
        if not moved:
            return count


@njit(**JIT)
def _carve(position, keys, state, lo, res):
    # Serial: a few thousand rays per view, and parallel writers would race on shared voxels.
    stamp = np.zeros(1)
    no_keys = np.zeros(0, dtype=np.int64)
    ox, oy, oz = position[0], position[1], position[2]
    for i in range(keys.shape[0]):
        ex, ey, ez = keys[i, 0], keys[i, 1], keys[i, 2]
        # Aim at the end voxel's centre; t_stop = 1 only guards against rounding at the end.
        dx = (ex + 0.5) * res - ox
        dy = (ey + 0.5) * res - oy
        dz = (ez + 0.5) * res - oz
        walk(ox, oy, oz, dx, dy, dz, 1.0, state, lo[0], lo[1], lo[2], res, MODE_CARVE, FALSE,
             ex, ey, ez, stamp, 1.0, no_keys)


@njit(**JIT)
def _carve_pixels(position, rot, fx, fy, cx, cy, width, height, stride, max_range, state, lo, res,
                  own, outer):
    # Serial, as _carve. Directions as in tpvp.nbv.information_gain._gains (pixel_ray_directions,
    # bit for bit). With returns outside the map (they may lie before it), rays walk from the
    # camera; otherwise they jump to the map's box.
    ncols = (width + stride - 1) // stride
    nrows = (height + stride - 1) // stride
    ox, oy, oz = position[0], position[1], position[2]
    skip = outer.size == 0
    for r in range(nrows):
        yn = (np.float64(r * stride) - cy) / fy
        for c in range(ncols):
            dx, dy, dz, t_stop = pixel_ray(rot, c, stride, yn, cx, fx, max_range)
            walk(ox, oy, oz, dx, dy, dz, t_stop, state, lo[0], lo[1], lo[2], res, MODE_FREESPACE,
                 skip, ZERO, ZERO, ZERO, own, 1.0, outer)
