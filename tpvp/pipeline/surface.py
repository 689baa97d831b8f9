"""What the views see of a planning surface, plants and rows alike."""

from __future__ import annotations

import numpy as np
from scipy import sparse

from tpvp.scene import voxels
from tpvp.scene.grid import build_grid
from tpvp.visibility import safe_visibility


def planning_visibility(planning_points, resolution: float, positions, look_ats, sensor):
    """The planning surface (``planning_points``: the transferred previous session with what was
    observed and the inflation) voxelised at ``resolution`` (the covering voxel), and what each
    view sees of it through ``sensor`` (ray casting, the dominant cost of planning; a camera inside
    an occupied voxel sees nothing): ``(grid, (views x planning voxels) csr)``."""
    grid = build_grid(voxels.voxelise(planning_points, resolution), resolution)
    return grid, safe_visibility(grid, positions, look_ats, sensor)


def with_captures_seen(visibility, grid, views, captures):
    """``visibility`` with every planning voxel that holds a point of view ``views[i]``'s capture
    ``captures[i]`` marked seen by that view (``selection.captures_seen``): a measurement proves its
    voxel was seen. Ray casting the planning grid alone does not know it where a noisy depth puts a
    point behind the surface it belongs to: that voxel would then ask for a view behind the leaf."""
    rows, columns = [], []
    for view, points in zip(views, captures):
        ids = np.unique(grid.ids_of(voxels.voxel_keys(points, grid.resolution)))
        ids = ids[ids >= 0]
        rows.append(np.full(len(ids), view, dtype=np.int64))
        columns.append(ids)
    if not rows:
        return visibility
    rows, columns = np.concatenate(rows), np.concatenate(columns)
    captured = sparse.csr_matrix((np.ones(len(rows), bool), (rows, columns)), shape=visibility.shape, dtype=bool)
    return (visibility + captured).astype(bool).tocsr()
