"""A capture's points count as seen by the view that took them (``selection.captures_seen``), and the
``realistic`` configuration is a robot's view of a plant."""

import numpy as np
from scipy import sparse

from tpvp.config_loading import load_config, make_config
from tpvp.pipeline.surface import with_captures_seen
from tpvp.scene import voxels
from tpvp.scene.grid import build_grid


def test_captured_voxels_are_marked_seen_by_their_view_and_nothing_else_changes():
    rng = np.random.default_rng(0)
    resolution = 0.01
    points = rng.uniform(0, 0.1, (400, 3))
    grid = build_grid(voxels.voxelise(points, resolution), resolution)
    ray_cast = sparse.random(5, grid.size, density=0.2, random_state=1, format="csr").astype(bool)
    captures = [points[:30], points[100:110] + 0.5, points[200:260]]  # the second lies outside the grid
    marked = with_captures_seen(ray_cast, grid, [3, 0, 1], captures)

    expected = ray_cast.toarray()
    for view, capture in zip([3, 0, 1], captures):  # brute force: each point's voxel by its coordinates
        for point in capture:
            key = np.floor(point / resolution).astype(np.int64)
            hits = np.flatnonzero((voxels.voxel_keys(grid.centres, resolution) == key).all(axis=1))
            expected[view, hits] = True
    assert marked.dtype == bool and isinstance(marked, sparse.csr_matrix)
    assert np.array_equal(marked.toarray(), expected)
    assert marked[1].sum() > ray_cast[1].sum() and np.array_equal(marked[2].toarray(), ray_cast[2].toarray())
    assert with_captures_seen(ray_cast, grid, [], []) is ray_cast


def test_captures_seen_is_off_in_paper_and_realistic_is_the_previous_frame_with_an_arm_camera():
    assert make_config("plant").selection.captures_seen is False
    realistic = load_config("realistic")
    assert (realistic.setting, realistic.scene.frame, realistic.sensor.noise) == ("plant", "previous", "arm-rgbd")
    paper = load_config("paper")
    assert (paper.scene.frame, paper.sensor.noise) == ("current", "ideal")


def test_the_world_table_s_current_ideal_rows_are_the_shipped_table_i():
    """benchmarks/results/table1_world.csv (notebook 02, docs/results.md): its `current` / `ideal` rows are the
    shipped Table I's Ours, so the other rows compare with the paper's protocol as shipped."""
    from tpvp.experiments import shipped
    from tpvp.experiments.notebooks import benchmark_results

    world = benchmark_results("table1_world")
    assert "84 cases" in world.source and len(world.raw) == 12
    rows = shipped.shipped_rows("table1")
    ours = rows[rows["method"] == "ours"].groupby("view_space")
    base = world.raw[(world.raw["frame"] == "current") & (world.raw["noise"] == "ideal")].set_index("view_space")
    for space in ("hemisphere", "sphere"):
        assert np.isclose(base.loc[space, "views"], ours["views"].mean()[space], rtol=5e-4)
        assert np.isclose(base.loc[space, "coverage_pct"], 100 * ours["coverage"].mean()[space], rtol=5e-5)
        assert base.loc[space, "cases"] == ours.size()[space]
