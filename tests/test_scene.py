"""Voxel grids, plant normalisation, view spaces and bundled samples."""

import numpy as np
import pytest

from tpvp.errors import ConfigError, InputFileError, PointCloudError
from tpvp.scene import voxels
from tpvp.scene.grid import build_grid
from tpvp.scene.normalise import normalise_plant, rotate_z, table_slab
from tpvp.scene.samples import load_sample
from tpvp.viewspace.single_plant import load_view_space
from tpvp.viewspace.space import INITIAL_VIEW_INDICES


def test_voxel_convention_is_octomaps():
    pts = np.array([[0.0, 0.0019, -0.0001], [0.002, 0.0041, -0.002]])
    keys = voxels.voxel_keys(pts, 0.002)
    np.testing.assert_array_equal(keys, [[0, 0, -1], [1, 2, -1]])
    np.testing.assert_allclose(voxels.key_centres(keys, 0.002), [[0.001, 0.001, -0.001], [0.003, 0.005, -0.001]])


def test_voxel_set_algebra_against_python_sets():
    rng = np.random.default_rng(0)
    a = rng.integers(-50, 50, size=(400, 3))
    b = rng.integers(-50, 50, size=(400, 3))
    sa, sb = set(map(tuple, a)), set(map(tuple, b))
    as_set = lambda k: set(map(tuple, k))
    assert as_set(voxels.union_keys(a, b)) == sa | sb
    assert as_set(voxels.intersect_keys(a, b)) == sa & sb
    assert as_set(voxels.difference_keys(a, b)) == sa - sb
    np.testing.assert_array_equal(voxels.contains_keys(a, b), [tuple(k) in sa for k in b])
    np.testing.assert_array_equal(voxels.decode_keys(voxels.encode_keys(a)), a)
    keys, counts = voxels.unique_keys(np.concatenate([a, a[:10]]), return_counts=True)
    assert len(keys) == len(sa) and counts.sum() == 410


def test_dilation_matches_brute_force():
    rng = np.random.default_rng(1)
    keys = voxels.unique_keys(rng.integers(0, 8, size=(20, 3)))
    for radius in (0, 1, 1.5, 2.3):
        fast = set(map(tuple, voxels.dilate_keys(keys, radius)))
        slow = set()
        r = int(np.floor(radius))
        for k in keys:
            for o in np.ndindex(2 * r + 1, 2 * r + 1, 2 * r + 1):
                o = np.array(o) - r
                if (o**2).sum() <= radius**2 + 1e-6:
                    slow.add(tuple(k + o))
        assert fast == slow
    assert len(voxels.spherical_offsets(1)) == 7


def test_voxel_errors():
    with pytest.raises(ConfigError):
        voxels.voxel_keys(np.zeros((1, 3)), 0)
    with pytest.raises(PointCloudError, match="NaN"):
        voxels.voxel_keys(np.array([[np.nan, 0, 0]]), 0.01)
    with pytest.raises(PointCloudError, match="units"):
        voxels.voxel_keys(np.array([[0, 0, 0], [7e5, 0, 0]]), 0.002)
    with pytest.raises(PointCloudError):
        build_grid(np.zeros((0, 3), np.int64), 0.01)


def test_normalisation_order_and_table():
    rng = np.random.default_rng(2)
    pts = rng.uniform([0, 0, 0], [40, 10, 25], size=(2000, 3)) + [100, -700, 5]
    scene = normalise_plant(pts, largest_side=0.24)
    ext = np.ptp(scene.points, axis=0)
    assert ext.max() == pytest.approx(0.24)
    np.testing.assert_allclose(scene.points.min(axis=0) + scene.points.max(axis=0), 0, atol=1e-12)
    # 45 degrees: the scale comes from the unrotated plant, the centre from the rotated one.
    rotated = normalise_plant(pts, largest_side=0.24, rotation_deg=45)
    assert rotated.scale == pytest.approx(scene.scale)
    # A 40 x 10 footprint turned by 45 degrees spans (40 + 10) / sqrt(2) along x and y.
    np.testing.assert_allclose(np.ptp(rotated.points[:, :2], axis=0), 50 / np.sqrt(2) * scene.scale, atol=0.01)
    np.testing.assert_allclose(rotated.points.min(axis=0) + rotated.points.max(axis=0), 0, atol=1e-12)
    np.testing.assert_allclose(rotated.transform(pts), rotated.points)
    np.testing.assert_allclose(rotate_z(np.array([[1.0, 0, 0]]), 90), [[0, 1, 0]], atol=1e-12)
    tabled = normalise_plant(pts, table=True)
    slab = tabled.table_points
    assert np.ptp(slab[:, 2]) == 0 and slab[0, 2] < tabled.points[:, 2].min()
    assert np.ptp(slab[:, 0]) == pytest.approx(0.4, abs=0.004)
    assert len(table_slab(tabled.points)) == len(slab)
    with pytest.raises(PointCloudError):
        normalise_plant(np.zeros((0, 3)))
    with pytest.raises(ConfigError):
        normalise_plant(pts, centre="middle")


def test_bundled_view_spaces_and_initial_views(tmp_path):
    hemi, sphere = load_view_space("hemisphere"), load_view_space("sphere")
    assert hemi.shape == (32, 3) and sphere.shape == (63, 3)
    np.testing.assert_allclose(np.linalg.norm(sphere, axis=1), 0.4, atol=1e-3)
    np.testing.assert_allclose(sphere[:32], hemi, atol=1e-6)  # the files round differently
    assert (hemi[:, 2] >= -1e-9).all()
    elevations = {k: np.degrees(np.arcsin(hemi[i, 2] / np.linalg.norm(hemi[i]))) for k, i in INITIAL_VIEW_INDICES.items()}
    assert elevations["near_horizontal"] == pytest.approx(7, abs=1)
    assert elevations["oblique"] == pytest.approx(48, abs=1)
    assert elevations["near_top"] == pytest.approx(77, abs=1)
    custom = tmp_path / "views.txt"
    custom.write_text("2\n1 0 0\n0 2 0\n")
    np.testing.assert_allclose(load_view_space(custom, radius=0.5), [[0.5, 0, 0], [0, 0.5, 0]])
    custom.write_text("3\n1 0 0\n0 2 0\n")
    with pytest.raises(InputFileError, match="declares 3"):
        load_view_space(custom)
    with pytest.raises(InputFileError, match="nowhere.txt"):
        load_view_space(tmp_path / "nowhere.txt")


def test_bundled_samples_are_real_scans_in_metres():
    tomato = load_sample("tomato_0306")
    assert tomato.shape == (50000, 3)
    assert 0.04 < np.ptp(tomato, axis=0).max() < 0.06  # 47.9 mm
    maize = load_sample("maize_0313")
    assert maize.shape == (338874, 3)
    with pytest.raises(ConfigError, match="unknown bundled sample"):
        load_sample("tomato_9999")


def test_generated_view_spaces_are_well_spread():
    from tpvp.viewspace.tammes import generate_view_space, min_angle_deg

    bundled = min_angle_deg(load_view_space("hemisphere"))
    hemi = generate_view_space(32, hemisphere=True)
    assert hemi.shape == (32, 3) and (hemi[:, 2] >= 0).all()
    np.testing.assert_allclose(np.linalg.norm(hemi, axis=1), 0.4)
    assert min_angle_deg(hemi) >= 0.95 * bundled  # as good as the authors' Tammes solution
    sphere = generate_view_space(63)
    assert min_angle_deg(sphere) >= 0.95 * min_angle_deg(load_view_space("sphere"))
    # Brute-force check of the helper on three hand-made directions.
    assert min_angle_deg(np.array([[1.0, 0, 0], [0, 1.0, 0], [1.0, 1.0, 0]])) == pytest.approx(45.0)
    np.testing.assert_array_equal(generate_view_space(5), generate_view_space(5))
    with pytest.raises(ConfigError):
        generate_view_space(0)
