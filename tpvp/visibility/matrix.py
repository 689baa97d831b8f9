"""Visibility matrices (views x voxels) and the oracle-normalised coverage of the paper (Eq. Omega)."""

from __future__ import annotations

import numpy as np
from scipy import sparse
from tqdm.auto import tqdm

from tpvp.scene.grid import OccupancyGrid
from tpvp.sensor.sensor import SensorConfig, observe_poses, view_poses


def visibility_matrix(grid: OccupancyGrid, positions, look_ats, config: SensorConfig = SensorConfig(),
                      chunk_size: int = 256, progress: bool | None = None) -> sparse.csr_matrix:
    """Sparse boolean matrix ``(views, voxels)``: ``[v, i]`` is True when view ``v`` observes voxel ``i``.

    Voxel ids are those of ``grid`` (non-countable voxels, e.g. the table, have empty columns).
    Views are processed in chunks, in parallel within a chunk; ``progress`` shows a bar
    (default: only for more than 1,000 views).
    """
    positions, rotations = view_poses(grid, positions, look_ats)
    if progress is None:
        progress = len(positions) > 1000
    blocks = []
    starts = range(0, len(positions), chunk_size)
    for start in tqdm(starts, desc="visibility", unit="chunk", disable=not progress):
        stop = start + chunk_size
        seen = observe_poses(grid, positions[start:stop], rotations[start:stop], config)
        blocks.append(sparse.csr_matrix(seen))
    if not blocks:
        return sparse.csr_matrix((0, grid.size), dtype=bool)
    return sparse.vstack(blocks, format="csr").astype(bool)


def safe_visibility(grid: OccupancyGrid, positions, look_ats, sensor: SensorConfig) -> sparse.csr_matrix:
    """:func:`visibility_matrix`, with an empty row for each view whose camera lies inside an
    occupied voxel (the sensor refuses such a camera; at a coarse covering voxel, a greenhouse
    candidate near a leaf can be one). ``look_ats``: one per view or one for all."""
    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    look_ats = np.broadcast_to(np.asarray(look_ats, dtype=np.float64).reshape(-1, 3), positions.shape)
    free = np.flatnonzero(~grid.is_occupied(positions))
    seen = visibility_matrix(grid, positions[free], look_ats[free], sensor, progress=False)
    rows = sparse.csr_matrix((np.ones(seen.nnz, bool), seen.indices, seen.indptr), shape=seen.shape).tocoo()
    return sparse.csr_matrix((rows.data, (free[rows.row], rows.col)), shape=(len(positions), grid.size), dtype=bool)


def oracle_voxels(matrix: sparse.spmatrix) -> np.ndarray:
    """Ids of voxels seen by at least one view (the oracle visible set Omega)."""
    return np.flatnonzero(np.asarray(matrix.sum(axis=0)).ravel() > 0)


def covered_voxels(matrix: sparse.spmatrix, views) -> np.ndarray:
    """Ids of voxels seen by at least one of the given views (row indices of ``matrix``)."""
    views = np.asarray(views, dtype=np.int64).reshape(-1)
    if views.size == 0:
        return np.zeros(0, dtype=np.int64)
    return oracle_voxels(matrix[views])


def coverage_ratio(covered, oracle) -> float:
    """``|covered & oracle| / |oracle|`` (paper's oracle-normalised surface coverage)."""
    oracle = np.asarray(oracle)
    if oracle.size == 0:
        return float("nan")
    return float(np.isin(oracle, np.asarray(covered)).sum() / oracle.size)
