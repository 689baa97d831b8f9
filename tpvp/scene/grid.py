"""Dense occupancy grid that the ray casters traverse.

A scene is a set of occupied voxels (keys, see :mod:`tpvp.scene.voxels`). For ray casting we store
them in a dense box padded by a few empty voxels:

* ``index[i, j, k]`` = id of the occupied voxel in ``keys`` (``-1`` when empty);
* ``clearance[i, j, k]`` = Chebyshev distance (in voxels) to the nearest occupied voxel, capped at
  255. Every voxel closer than that is empty, which lets a ray jump through empty space without
  changing which voxel it meets first (see :mod:`tpvp.sensor.raycast`);
* ``countable[id]`` = whether a hit on that voxel counts as an observation. Supporting-table voxels
  occlude but never count (docs/sensor.md#coverage).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from tpvp.errors import ConfigError, PointCloudError
from tpvp.scene import voxels

PAD = 2  # empty voxels around the occupied box; >= 1 is required by the entry skip
_MAX_CELLS = 400_000_000


@dataclass(frozen=True, eq=False)
class OccupancyGrid:
    resolution: float
    keys: np.ndarray  # (N, 3) int64 occupied voxel keys, id = row
    countable: np.ndarray  # (N,) bool
    origin_key: np.ndarray  # (3,) int64 key of dense cell [0, 0, 0]
    index: np.ndarray  # (X, Y, Z) int32
    clearance: np.ndarray  # (X, Y, Z) uint8

    @property
    def size(self) -> int:
        return len(self.keys)

    @property
    def centres(self) -> np.ndarray:
        return voxels.key_centres(self.keys, self.resolution)

    @property
    def countable_ids(self) -> np.ndarray:
        return np.flatnonzero(self.countable)

    def ids_of(self, keys: np.ndarray) -> np.ndarray:
        """Voxel ids of keys (``-1`` for keys that are not occupied)."""
        local = np.asarray(keys, dtype=np.int64).reshape(-1, 3) - self.origin_key
        inside = np.all((local >= 0) & (local < np.array(self.index.shape)), axis=1)
        ids = np.full(len(local), -1, dtype=np.int64)
        ids[inside] = self.index[tuple(local[inside].T)]
        return ids

    def is_occupied(self, points: np.ndarray) -> np.ndarray:
        return self.ids_of(voxels.voxel_keys(points, self.resolution)) >= 0


def build_grid(keys: np.ndarray, resolution: float, countable: np.ndarray | None = None) -> OccupancyGrid:
    """Dense grid from occupied voxel keys (duplicates are merged, order becomes the code order)."""
    keys = np.asarray(keys, dtype=np.int64).reshape(-1, 3)
    if len(keys) == 0:
        raise PointCloudError("cannot build an occupancy grid from an empty voxel set")
    if countable is None:
        countable = np.ones(len(keys), dtype=bool)
    countable = np.asarray(countable, dtype=bool).reshape(-1)
    if countable.shape != (len(keys),):
        raise ConfigError(f"countable mask has {countable.size} entries for {len(keys)} voxels")
    all_codes = voxels.encode_keys(keys)
    codes, first, inverse = np.unique(all_codes, return_index=True, return_inverse=True)
    del all_codes
    # A voxel is countable if any of its duplicates is (a plant voxel wins over a table voxel).
    merged_countable = np.zeros(len(codes), dtype=bool)
    merged_countable[inverse[countable]] = True
    keys = keys[first]

    origin = keys.min(axis=0) - PAD
    shape = keys.max(axis=0) + PAD + 1 - origin
    if int(np.prod(shape)) > _MAX_CELLS:
        raise PointCloudError(
            f"scene spans {shape.tolist()} voxels of {resolution} m; too large for a dense grid "
            "(wrong units or a too fine resolution?)"
        )
    index = np.full(tuple(shape), -1, dtype=np.int32)
    local = keys - origin
    index[tuple(local.T)] = np.arange(len(keys), dtype=np.int32)
    # Chebyshev distance to the nearest occupied cell; occupied cells get 0.
    clearance = ndimage.distance_transform_cdt(index < 0, metric="chessboard")
    clearance = np.minimum(clearance, 255).astype(np.uint8)
    return OccupancyGrid(
        resolution=float(resolution),
        keys=keys,
        countable=merged_countable,
        origin_key=origin.astype(np.int64),
        index=index,
        clearance=clearance,
    )


def grid_from_points(points: np.ndarray, resolution: float, countable_points=None) -> OccupancyGrid:
    """Voxelise a cloud (and optionally mark which points count) into an :class:`OccupancyGrid`."""
    keys = voxels.voxel_keys(points, resolution)
    if len(keys) == 0:
        raise PointCloudError("cannot build an occupancy grid from an empty point cloud")
    return build_grid(keys, resolution, countable_points)


def plant_grid(plant_points: np.ndarray, table_points: np.ndarray, resolution: float) -> OccupancyGrid:
    """Ground truth of a single-plant scene: plant voxels count, supporting-table voxels only occlude."""
    plant = voxels.voxelise(plant_points, resolution)
    table = voxels.difference_keys(voxels.voxelise(np.asarray(table_points).reshape(-1, 3), resolution), plant)
    return build_grid(np.concatenate([plant, table]), resolution,
                      np.r_[np.ones(len(plant), bool), np.zeros(len(table), bool)])
