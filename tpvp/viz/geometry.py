"""What the pictures of a plan draw, as arrays (no plotting library)."""

from __future__ import annotations

import numpy as np

from tpvp.path.local import local_path_points
from tpvp.visibility import covered_voxels


def path_polyline(positions, centre, radius) -> np.ndarray:
    """The path through ``positions`` in order, each move around the obstacle sphere."""
    if len(positions) < 2:
        return np.asarray(positions)
    return np.concatenate([local_path_points(a, b, centre, radius) for a, b in zip(positions[:-1], positions[1:])])


def plan_geometry(scene, result) -> dict:
    """What the pictures of a plant plan draw: the executed views' positions in order, the path
    around the obstacle sphere, and per ground-truth voxel whether the plan covered it and whether
    any view could (the oracle set)."""
    order = result.order
    positions = scene.view_space.positions[order]
    polyline = path_polyline(positions, *result.obstacle)
    covered = np.zeros(scene.grid.size, bool)
    covered[covered_voxels(scene.truth_visibility, order)] = True
    observable = np.zeros(scene.grid.size, bool)
    observable[scene.oracle] = True
    return {"positions": positions, "polyline": polyline, "covered": covered, "observable": observable}
