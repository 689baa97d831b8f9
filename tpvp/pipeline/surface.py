"""What the views see of a planning surface, plants and rows alike."""

from __future__ import annotations

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
