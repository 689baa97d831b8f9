"""The depth images a simulated session captures and the model fused from them
(tpvp.simulate.depth_captures): the exact image back-projected lands on the ground truth, a noisy
one is the sensor's draw at the reported pose, and the fused model lies on today's plant, without
the table."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from tpvp.config_loading import load_config
from tpvp.scene.frame import scan_points
from tpvp.sensor.noise import apply_depth_noise, noise_profile
from tpvp.simulate.depth_captures import captured_frame, fused_captures, rendered_depth, sensor_pose
from tpvp.simulate.world import build_scene
from tpvp.synthetic.plants import generate_plant
from tpvp.visibility import covered_voxels

VIEWS = (0, 7, 19, 28)


@pytest.fixture(scope="module")
def scenes():
    plant = generate_plant("tomato", 0).points
    return {noise: build_scene(plant, plant, load_config("paper", {"sensor.noise": noise}))
            for noise in ("ideal", "phone-lidar")}


def back_projected(frame) -> np.ndarray:
    """Every pixel with depth, back-projected by hand (sensor's world)."""
    v, u = np.nonzero(frame.depth > 0)
    z = frame.depth[v, u].astype(np.float64)
    k = frame.intrinsics
    camera = np.stack([(u - k.cx) / k.fx * z, (v - k.cy) / k.fy * z, z], axis=1)
    return camera @ frame.camera_to_world[:3, :3].T + frame.camera_to_world[:3, 3]


def test_an_exact_image_lands_on_the_ground_truth(scenes):
    scene = scenes["ideal"]
    grid = scene.grid
    for view in VIEWS:
        frame = captured_frame(scene, view)
        assert np.array_equal(frame.depth, (rendered_depth(scene, view) / scene.per_metre).astype(np.float32))
        pose = sensor_pose(scene, view)
        assert np.array_equal(frame.camera_to_world, pose)
        forward = scene.view_space.look_ats[view] - scene.view_space.positions[view]
        assert np.allclose(pose[:3, 2], forward / np.linalg.norm(forward))  # OpenCV: +z looks at the target
        points = back_projected(frame) * scene.per_metre
        assert len(points) > 1000
        # each first-surface point lies on an occupied voxel's boundary: within half a diagonal of its centre
        distance, _ = cKDTree(grid.centres).query(points)
        assert distance.max() <= 0.5 * np.sqrt(3) * grid.resolution * (1 + 1e-3)


def test_a_noisy_image_is_the_sensors_draw_at_the_reported_pose(scenes):
    scene = scenes["phone-lidar"]
    profile = noise_profile("phone-lidar")
    for capture, view in enumerate(VIEWS):
        frame = captured_frame(scene, view, capture, len(VIEWS))
        rng = np.random.default_rng([scene.seed, view, capture])
        depth, pose = apply_depth_noise(profile, rendered_depth(scene, view) / scene.per_metre,
                                        scene.sensor.intrinsics, sensor_pose(scene, view), capture, len(VIEWS), rng,
                                        drift_seed=scene.seed)
        assert np.array_equal(frame.depth, depth.astype(np.float32)) and np.array_equal(frame.camera_to_world, pose)
        assert not np.array_equal(frame.camera_to_world, sensor_pose(scene, view))


@pytest.mark.parametrize("noise, within", [("ideal", 1.0), ("phone-lidar", 3.0)])
def test_the_fused_model_lies_on_todays_plant_without_the_table(scenes, noise, within):
    """Fused in the scan's frame; brought into the planning frame, the model lies within ``within``
    fusion voxels (5 mm of the sensor's world) of the voxels the views saw, holds most of them, and
    nothing of the table."""
    scene = scenes[noise]
    fused = fused_captures(scene, VIEWS)
    matrix = scene.plant_from_scan
    planning = fused @ matrix[:3, :3].T + matrix[:3, 3]
    assert np.allclose(scan_points(matrix, planning), fused)
    seen = scene.grid.centres[covered_voxels(scene.truth_visibility, list(VIEWS))]
    voxel = 0.005 * scene.per_metre
    to_seen, _ = cKDTree(seen).query(planning)
    assert np.percentile(to_seen, 99) <= within * voxel
    held, _ = cKDTree(planning).query(seen)
    assert (held <= voxel).mean() >= 0.9
    assert planning[:, 2].min() > scene.table_points[:, 2].max() + voxel
