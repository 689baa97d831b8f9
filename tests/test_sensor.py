"""Virtual sensor: numba kernels against the plain-numpy brute force, exact hit sets."""

import numpy as np
import pytest

from tpvp.errors import ConfigError, SensorError
from tpvp.scene import voxels
from tpvp.scene.grid import build_grid
from tpvp.sensor import bruteforce
from tpvp.sensor.camera import D435, in_frustum, look_at_rotation, rotation_to_quaternion
from tpvp.sensor.raycast import cast_ray
from tpvp.sensor.sensor import SensorConfig, depth_image, observe, observe_many, observe_poses, view_poses


def random_scene(seed, n=250, box=14, res=0.01, planes=True):
    """Random voxels plus a few thin walls (so occlusion happens) and some non-countable voxels."""
    rng = np.random.default_rng(seed)
    keys = rng.integers(-box // 2, box // 2, size=(n, 3))
    if planes:
        a, b = np.meshgrid(np.arange(-4, 4), np.arange(-4, 4))
        wall = np.stack([np.full(a.size, 2), a.ravel(), b.ravel()], axis=1)
        floor = np.stack([a.ravel(), b.ravel(), np.full(a.size, -6)], axis=1)
        keys = np.concatenate([keys, wall, floor])
    keys = voxels.unique_keys(keys)
    countable = rng.random(len(keys)) > 0.15
    return build_grid(keys, res, countable)


def random_cameras(seed, count, radius, centre=np.zeros(3)):
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(count, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    positions = centre + d * radius * rng.uniform(0.8, 1.2, size=(count, 1))
    look_ats = centre + rng.normal(scale=0.2 * radius, size=(count, 3))
    return positions, look_ats


@pytest.mark.parametrize("seed", range(6))
def test_reference_model_matches_bruteforce_small(seed):
    grid = random_scene(seed)
    positions, look_ats = random_cameras(seed + 100, 8, radius=0.25)
    for p, t in zip(positions, look_ats):
        fast = observe(grid, p, t, SensorConfig(max_range=0.3))
        slow = bruteforce.reference_observation(grid, p, t, max_range=0.3)
        np.testing.assert_array_equal(fast, slow)


@pytest.mark.parametrize("seed", range(4))
def test_pixel_model_matches_bruteforce_small(seed):
    grid = random_scene(seed, res=0.02)
    positions, look_ats = random_cameras(seed + 200, 4, radius=0.6)
    config = SensorConfig(model="pixel", pixel_stride=7, max_range=0.7)
    for p, t in zip(positions, look_ats):
        fast = observe(grid, p, t, config)
        slow, image = bruteforce.pixel_observation(grid, p, t, max_range=0.7, stride=7, return_image=True)
        np.testing.assert_array_equal(fast, slow)
        depth, hit = depth_image(grid, p, t, config)
        np.testing.assert_array_equal(hit, image)
        assert np.all(np.isfinite(depth[hit >= 0])) and np.all(np.isinf(depth[hit < 0]))


def test_camera_inside_the_box_of_voxels():
    # Cameras inside the dense grid (between voxels) start the walk without the entry skip.
    grid = random_scene(7, n=400, box=30)
    positions, look_ats = random_cameras(8, 10, radius=0.05)
    positions = positions[~grid.is_occupied(positions)]
    for p, t in zip(positions, look_ats):
        np.testing.assert_array_equal(observe(grid, p, t), bruteforce.reference_observation(grid, p, t))


def test_first_hit_of_a_single_ray_is_the_nearest_voxel():
    keys = np.array([[5, 0, 0], [8, 0, 0], [5, 3, 0]])
    grid = build_grid(keys, 0.1)
    hit = cast_ray(0.0501, 0.0502, 0.0503, 1.0, 0.0001, 0.0, grid.index, grid.clearance,
                   *grid.origin_key, 0.1, np.inf, np.inf)
    assert tuple(grid.keys[hit]) == (5, 0, 0)
    # The same ray from behind the first voxel sees the second one.
    hit = cast_ray(0.65, 0.05, 0.05, 1.0, 0.0001, 0.0, grid.index, grid.clearance,
                   *grid.origin_key, 0.1, np.inf, np.inf)
    assert tuple(grid.keys[hit]) == (8, 0, 0)
    # Out of range: nothing.
    hit = cast_ray(0.0501, 0.0502, 0.0503, 1.0, 0.0001, 0.0, grid.index, grid.clearance,
                   *grid.origin_key, 0.1, 0.3**2, np.inf)
    assert hit == -1


def test_hand_checked_occlusion():
    # A 3x3 wall in front of a 3x3 panel: from straight ahead the wall hides the panel centre.
    res = 0.01
    a, b = np.meshgrid(np.arange(-1, 2), np.arange(-1, 2))
    wall = np.stack([np.zeros(9, int), a.ravel(), b.ravel()], axis=1)
    panel = wall + [5, 0, 0]
    grid = build_grid(np.concatenate([wall, panel]), res)
    seen = grid.keys[observe(grid, [-0.2001, 0.0003, 0.0002], [0.1, 0.0, 0.0])]
    assert {tuple(k) for k in seen} == {tuple(k) for k in wall}
    # From the far side the panel is seen and the wall is hidden.
    seen = grid.keys[observe(grid, [0.3001, 0.0003, 0.0002], [0.0, 0.0, 0.0])]
    assert {tuple(k) for k in seen} == {tuple(k) for k in panel}


def test_non_countable_voxels_occlude_but_never_count():
    res = 0.01
    a, b = np.meshgrid(np.arange(-1, 2), np.arange(-1, 2))
    table = np.stack([np.zeros(9, int), a.ravel(), b.ravel()], axis=1)
    plant = table + [5, 0, 0]
    keys = np.concatenate([table, plant])
    grid = build_grid(keys, res, np.r_[np.zeros(9, bool), np.ones(9, bool)])
    assert observe(grid, [-0.2001, 0.0003, 0.0002], [0.1, 0.0, 0.0]).size == 0
    for model in ("reference", "pixel"):
        seen = observe(grid, [0.3001, 0.0003, 0.0002], [0.0, 0.0, 0.0], SensorConfig(model=model))
        assert {tuple(k) for k in grid.keys[seen]} == {tuple(k) for k in plant}


def test_observe_many_equals_single_views():
    grid = random_scene(3)
    positions, look_ats = random_cameras(4, 6, radius=0.25)
    for model in ("reference", "pixel"):
        config = SensorConfig(model=model, pixel_stride=5)
        matrix = observe_many(grid, positions, look_ats, config)
        for row, p, t in zip(matrix, positions, look_ats):
            np.testing.assert_array_equal(np.flatnonzero(row), observe(grid, p, t, config))
        # The public pose form behind observe_many and the visibility matrix.
        np.testing.assert_array_equal(observe_poses(grid, *view_poses(grid, positions, look_ats), config),
                                      matrix)


@pytest.mark.slow
def test_reference_model_matches_bruteforce_on_real_tomato(tomato_scene):
    grid, views = tomato_scene
    for p in views[[0, 17, 8, 21]]:
        np.testing.assert_array_equal(observe(grid, p, np.zeros(3)),
                                      bruteforce.reference_observation(grid, p, np.zeros(3)))


@pytest.mark.slow
def test_pixel_model_matches_bruteforce_on_real_tomato(tomato_scene):
    grid, views = tomato_scene
    config = SensorConfig(model="pixel", pixel_stride=3)
    for p in views[[17, 21]]:
        fast = observe(grid, p, np.zeros(3), config)
        slow = bruteforce.pixel_observation(grid, p, np.zeros(3), stride=3)
        np.testing.assert_array_equal(fast, slow)
        assert len(fast) > 300


def test_camera_pose_conventions():
    rot = look_at_rotation([1.0, 0.0, 0.0], [0.0, 0.0, 0.0])
    np.testing.assert_allclose(rot[:, 2], [-1, 0, 0])  # optical axis toward the target
    np.testing.assert_allclose(rot[:, 1], [0, 0, -1])  # image down = world down
    for position in ([0, 0, 1.0], [0, 0, -1.0], [1e-12, 0, 2.0]):
        rot = look_at_rotation(position, [0, 0, 0])
        assert np.all(np.isfinite(rot))
        np.testing.assert_allclose(rot.T @ rot, np.eye(3), atol=1e-12)
        assert np.linalg.det(rot) == pytest.approx(1.0)
    q = rotation_to_quaternion(look_at_rotation([0.3, -0.2, 0.1], [0, 0, 0]))
    assert np.linalg.norm(q) == pytest.approx(1.0)
    # The look-at target projects to the principal point.
    assert in_frustum(np.zeros((1, 3)), np.array([0.3, -0.2, 0.1]), look_at_rotation([0.3, -0.2, 0.1], [0, 0, 0]))[0]
    assert D435.width == 1280 and D435.height == 720


def test_bad_views_raise_clear_errors():
    grid = random_scene(0)
    with pytest.raises(SensorError, match="zero-length look-at"):
        observe(grid, [0.3, 0.3, 0.3], [0.3, 0.3, 0.3])
    inside = grid.centres[0]
    with pytest.raises(SensorError, match="inside the geometry"):
        observe(grid, inside, inside + 1.0)
    with pytest.raises(SensorError, match="not finite"):
        observe(grid, [np.nan, 0, 0], [0, 0, 0])
    with pytest.raises(ConfigError, match="unknown sensor model"):
        SensorConfig(model="lidar")
    with pytest.raises(ConfigError, match="max_range"):
        SensorConfig(max_range=0)
