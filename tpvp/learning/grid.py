"""The learned planners' input: a 32^3 OctoMap-style occupancy grid of what the executed views saw.

As in MA-SCVP (docs/learning.md#grid): a cube of half-size ``R = 17/16 x`` the largest distance of
an observed point from the view-space centre, split into 32 cells per side; every cell starts
unknown (log-odds 0, probability 0.5). Each view's cloud is ray-inserted from the camera as OctoMap
does: the cells holding a point are *occupied* for that scan, every cell a ray crosses before its
point's cell is *free* (occupied wins), and each cell is updated once per scan with the hit (0.7)
or miss (0.4) log-odds, clamped to [0.1192, 0.971]. The grid is read out as probabilities with x
outermost and z fastest (``grid[x, y, z]``).

Deviations from the published recipe, both so that training and planning see the same input: the
cube is sized on the observed points (not the ground-truth model) and holds what the pipeline
observes, the segmented plant (the table occludes in the renders but is not inserted).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from tpvp.errors import PointCloudError

CELLS = 32
SIZE_FACTOR = 17 / 16
P_HIT, P_MISS, P_MIN, P_MAX = 0.7, 0.4, 0.1192, 0.971


def _logit(p: float) -> float:
    return math.log(p / (1 - p))


L_HIT, L_MISS, L_MIN, L_MAX = (_logit(p) for p in (P_HIT, P_MISS, P_MIN, P_MAX))


@dataclass(frozen=True)
class GridGeometry:
    """The cube ``lower .. lower + CELLS * cell`` (m)."""

    lower: np.ndarray
    cell: float

    @classmethod
    def around(cls, centre, points, cells: int = CELLS) -> "GridGeometry":
        """The cube centred on ``centre`` with half-size 17/16 x the farthest observed point."""
        centre = np.asarray(centre, dtype=np.float64).reshape(3)
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if len(points) == 0:
            raise PointCloudError("the executed views observed no point: the learned planner has no input")
        radius = SIZE_FACTOR * float(np.sqrt(((points - centre) ** 2).sum(axis=1).max()))
        if not radius > 0:
            raise PointCloudError("every observed point lies on the view-space centre: the input grid has no size")
        return cls(centre - radius, 2 * radius / cells)

    def to_cells(self, points) -> np.ndarray:
        """Points in cell units (cell ``k`` spans ``[k, k + 1)``)."""
        return (np.asarray(points, dtype=np.float64).reshape(-1, 3) - self.lower) / self.cell


@njit(cache=True)
def _insert_rays(origin, ends, n, occupied, free):
    """Mark each end's cell occupied and every cell the segment origin -> end crosses before it free
    (exact 3D DDA in cell units, clipped to the grid ``[0, n)^3``)."""
    for i in range(ends.shape[0]):
        d0 = ends[i, 0] - origin[0]
        d1 = ends[i, 1] - origin[1]
        d2 = ends[i, 2] - origin[2]
        e0 = int(math.floor(ends[i, 0]))
        e1 = int(math.floor(ends[i, 1]))
        e2 = int(math.floor(ends[i, 2]))
        if 0 <= e0 < n and 0 <= e1 < n and 0 <= e2 < n:
            occupied[e0, e1, e2] = True
        # clip the segment t in [0, 1] to the grid box
        t0, t1 = 0.0, 1.0
        for axis in range(3):
            o = origin[axis]
            d = d0 if axis == 0 else (d1 if axis == 1 else d2)
            if d == 0.0:
                if o < 0.0 or o >= n:
                    t0 = 2.0
            else:
                a = (0.0 - o) / d
                b = (n - o) / d
                if a > b:
                    a, b = b, a
                t0 = max(t0, a)
                t1 = min(t1, b)
        if t0 >= t1:
            continue
        # the entry cell: the point just after the entry, clamped into the grid
        tm = t0 + 1e-9 * (t1 - t0)
        k0 = min(max(int(math.floor(origin[0] + tm * d0)), 0), n - 1)
        k1 = min(max(int(math.floor(origin[1] + tm * d1)), 0), n - 1)
        k2 = min(max(int(math.floor(origin[2] + tm * d2)), 0), n - 1)
        s0 = 1 if d0 > 0 else -1
        s1 = 1 if d1 > 0 else -1
        s2 = 1 if d2 > 0 else -1
        inf = 1e30
        m0 = ((k0 + (s0 > 0)) - origin[0]) / d0 if d0 != 0.0 else inf
        m1 = ((k1 + (s1 > 0)) - origin[1]) / d1 if d1 != 0.0 else inf
        m2 = ((k2 + (s2 > 0)) - origin[2]) / d2 if d2 != 0.0 else inf
        a0 = abs(1.0 / d0) if d0 != 0.0 else inf
        a1 = abs(1.0 / d1) if d1 != 0.0 else inf
        a2 = abs(1.0 / d2) if d2 != 0.0 else inf
        while True:
            if k0 == e0 and k1 == e1 and k2 == e2:
                break
            free[k0, k1, k2] = True
            if m0 <= m1 and m0 <= m2:
                if m0 > t1:
                    break
                k0 += s0
                m0 += a0
            elif m1 <= m2:
                if m1 > t1:
                    break
                k1 += s1
                m1 += a1
            else:
                if m2 > t1:
                    break
                k2 += s2
                m2 += a2
            if not (0 <= k0 < n and 0 <= k1 < n and 0 <= k2 < n):
                break


def scan_cells(geometry: GridGeometry, camera, points, cells: int = CELLS) -> tuple[np.ndarray, np.ndarray]:
    """One scan's update: flat ids (C order) of its occupied cells and of its free cells."""
    occupied = np.zeros((cells,) * 3, dtype=np.bool_)
    free = np.zeros((cells,) * 3, dtype=np.bool_)
    ends = geometry.to_cells(points)
    if len(ends):
        _insert_rays(geometry.to_cells(camera)[0], ends, cells, occupied, free)
    free &= ~occupied
    return np.flatnonzero(occupied), np.flatnonzero(free)


def log_odds_grid(geometry: GridGeometry, cameras, clouds, cells: int = CELLS) -> np.ndarray:
    """The clamped log-odds of every cell after inserting ``clouds[i]`` from ``cameras[i]`` in order."""
    log_odds = np.zeros(cells ** 3, dtype=np.float64)
    for camera, points in zip(cameras, clouds):
        occupied, free = scan_cells(geometry, camera, points, cells)
        log_odds[occupied] = np.minimum(log_odds[occupied] + L_HIT, L_MAX)
        log_odds[free] = np.maximum(log_odds[free] + L_MISS, L_MIN)
    return log_odds.reshape((cells,) * 3)


def occupancy_grid(centre, cameras, clouds, cells: int = CELLS) -> np.ndarray:
    """The network input, ``float32 (cells, cells, cells)`` probabilities: unknown 0.5, free below,
    occupied above. ``cameras``: ``(k, 3)`` view positions; ``clouds``: the ``k`` observed clouds."""
    clouds = [np.asarray(c, dtype=np.float64).reshape(-1, 3) for c in clouds]
    geometry = GridGeometry.around(centre, np.concatenate(clouds) if clouds else np.zeros((0, 3)), cells)
    log_odds = log_odds_grid(geometry, np.asarray(cameras, dtype=np.float64).reshape(-1, 3), clouds, cells)
    return (1.0 / (1.0 + np.exp(-log_odds))).astype(np.float32)
