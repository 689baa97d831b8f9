"""What a handheld scan of a generated row would have captured.

The paper's reference rows are not complete surfaces: each session was scanned by a person walking
the aisle with a LiDAR phone (Polycam) and reconstructed with NeRF, so a reference model holds only
surfaces a sensor in the aisle saw. A generated row holds every surface, including leaves deep in
the canopy that no scan would contain; planned on as ground truth, those make the oracle larger and
harder to reach than the paper's (measured: the 800 candidates of a prior reach 89.7-91.2 % of the
oracle instead of 94.5-97.3 %). :func:`handheld_scan` keeps the points a sweep of the room's aisle
observes: from every candidate position of the room (the aisle side of the row), the reference
sensor looks straight across the row and ``offset`` metres to the left, right, up and down of that
point on the row's mid-plane, at a ``resolution`` voxel grid (the reconstruction's detail).
"""

from __future__ import annotations

import numpy as np

from tpvp.errors import checked_cloud
from tpvp.scene import voxels
from tpvp.scene.grid import build_grid
from tpvp.sensor.sensor import ROW_RANGE, SensorConfig
from tpvp.visibility import covered_voxels, safe_visibility

SCAN_OFFSETS = ((0.0, 0.0), (1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0))  # (along, up) x offset


def handheld_scan(points, room, resolution: float = 0.02, offset: float = 0.3,
                  max_range: float = ROW_RANGE) -> np.ndarray:
    """Boolean mask of the ``points`` (a row in ``room``'s frame) whose ``resolution`` voxel the
    aisle sweep observes (see the module doc)."""
    points = checked_cloud(points, "row")
    grid = build_grid(voxels.voxelise(points, resolution), resolution)
    box = room.plant_box
    local = box.to_local(room.candidate_positions)
    positions, look_ats = [], []
    for along, up in SCAN_OFFSETS:
        target = local.copy()
        target[:, 1] = 0.0  # the row's mid-plane
        target[:, 0] += along * offset
        target[:, 2] += up * offset
        positions.append(room.candidate_positions)
        look_ats.append(box.to_world(target))
    visibility = safe_visibility(grid, np.concatenate(positions), np.concatenate(look_ats), SensorConfig(max_range=max_range))
    seen = covered_voxels(visibility, np.arange(visibility.shape[0]))
    return np.isin(grid.ids_of(voxels.voxel_keys(points, resolution)), seen)
