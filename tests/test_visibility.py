"""Visibility matrix, oracles and coverage against brute-force references."""

import numpy as np
import pytest
from scipy import sparse

from tpvp.errors import ConfigError
from tpvp.sensor import bruteforce
from tpvp.sensor.sensor import SensorConfig, observe
from tpvp.visibility import coverage_ratio, covered_voxels, oracle_voxels, safe_visibility, visibility_matrix
from tpvp.visibility.oracle import greenhouse_oracle

from test_sensor import random_cameras, random_scene


def test_visibility_matrix_rows_are_observations():
    grid = random_scene(11)
    positions, look_ats = random_cameras(12, 9, radius=0.25)
    for model in ("reference", "pixel"):
        config = SensorConfig(model=model, pixel_stride=6)
        matrix = visibility_matrix(grid, positions, look_ats, config, chunk_size=4)
        assert sparse.issparse(matrix) and matrix.shape == (9, grid.size) and matrix.dtype == bool
        for v in range(9):
            np.testing.assert_array_equal(matrix[v].indices, observe(grid, positions[v], look_ats[v], config))
        # Non-countable voxels never appear.
        assert not matrix[:, ~grid.countable].nnz


def test_safe_visibility_gives_a_camera_inside_the_geometry_an_empty_row():
    grid = random_scene(11)
    positions, look_ats = random_cameras(12, 6, radius=0.25)
    inside = grid.centres[np.flatnonzero(grid.countable)[0]]
    positions = np.insert(positions, 2, inside, axis=0)
    look_ats = np.insert(look_ats, 2, look_ats[0], axis=0)
    matrix = safe_visibility(grid, positions, look_ats, SensorConfig())
    free = np.delete(np.arange(7), 2)
    assert matrix.shape == (7, grid.size) and matrix.dtype == bool and matrix[2].nnz == 0
    assert (matrix[free] != visibility_matrix(grid, positions[free], look_ats[free])).nnz == 0


def test_oracle_and_coverage_by_hand():
    matrix = sparse.csr_matrix(np.array([[1, 1, 0, 0, 0], [0, 1, 1, 0, 0], [0, 0, 0, 0, 1]], dtype=bool))
    np.testing.assert_array_equal(oracle_voxels(matrix), [0, 1, 2, 4])
    np.testing.assert_array_equal(covered_voxels(matrix, [0, 1]), [0, 1, 2])
    assert coverage_ratio(covered_voxels(matrix, [0, 1]), oracle_voxels(matrix)) == pytest.approx(0.75)
    assert covered_voxels(matrix, []).size == 0
    assert np.isnan(coverage_ratio([1], []))


@pytest.mark.slow
def test_hemisphere_oracle_of_real_tomato(tomato_scene):
    grid, views = tomato_scene
    matrix = visibility_matrix(grid, views, np.zeros(3))
    oracle = oracle_voxels(matrix)
    slow = np.unique(np.concatenate([bruteforce.reference_observation(grid, p, np.zeros(3)) for p in views[::8]]))
    assert np.isin(slow, oracle).all()
    # Most of the plant is visible from the hemisphere, not all of it (self-occlusion, table).
    assert 0.7 * grid.countable.sum() < len(oracle) < grid.countable.sum()


def bruteforce_greenhouse_oracle(grid, viewpoints, max_range):
    visible = np.zeros(grid.size, bool)
    centres = grid.centres
    for i in np.flatnonzero(grid.countable):
        d2 = ((viewpoints - centres[i]) ** 2).sum(axis=1)
        order = np.argsort(d2, kind="stable")
        order = order[d2[order] <= max_range**2]
        for g in order:
            hit = bruteforce.march_rays(grid, viewpoints[g], centres[i] - viewpoints[g], max_range)[0]
            if hit == i:
                visible[i] = True
                break
            if hit >= 0:
                visible[hit] = True
    return np.flatnonzero(visible & grid.countable)


@pytest.mark.parametrize("seed", range(3))
def test_greenhouse_oracle_matches_bruteforce(seed):
    grid = random_scene(seed, n=200, box=12, res=0.05)
    rng = np.random.default_rng(seed)
    viewpoints = rng.uniform(-0.6, 0.6, size=(40, 3)) + [0.0, 0.0, 0.0]
    viewpoints = viewpoints[~grid.is_occupied(viewpoints)]
    fast = greenhouse_oracle(grid, viewpoints, max_range=0.7, first_tries=3, chunk_size=50)
    np.testing.assert_array_equal(fast, bruteforce_greenhouse_oracle(grid, viewpoints, 0.7))


def test_greenhouse_oracle_errors():
    grid = random_scene(0)
    with pytest.raises(ConfigError):
        greenhouse_oracle(grid, np.zeros((0, 3)))
    with pytest.raises(ConfigError):
        greenhouse_oracle(grid, np.ones((1, 3)), max_range=0)
