"""Sensor noise on depth images (tpvp.sensor.noise.apply_depth_noise) and the stand-in phone's
``--noise``: each error against a brute force or its statistics, the reported pose against
pose_error's draw, determinism, ``ideal`` bit for bit, and an unknown profile refused with one line."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from data_tools import cli
from data_tools.capture.formats import load_depth, read_capture
from data_tools.capture.phone_standin import PHONE_LANDSCAPE, noisy_frames, plant_scene, render
from tpvp.sensor.noise import ARM_RGBD, IDEAL, PHONE_LIDAR, NoiseProfile, apply_depth_noise, pose_error

K = PHONE_LANDSCAPE  # 256 x 192, f = 212 px
NO_POSE = dict(jitter_m=0.0, jitter_deg=0.0, drift_m=0.0, drift_deg=0.0)
SIGMA_ONLY = dataclasses.replace(PHONE_LIDAR, dropout=0.0, mixed_pixels=0.0, **NO_POSE)


def true_pose(angle: float = 0.3) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    pose = np.eye(4)
    turn = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    pose[:3, :3] = turn @ np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])
    pose[:3, 3] = [0.4, -0.2, 0.3]
    return pose


def stretch() -> np.ndarray:
    """Ray distance per unit of z at every pixel, brute force."""
    out = np.empty((K.height, K.width))
    for v in range(K.height):
        for u in range(K.width):
            out[v, u] = np.linalg.norm([(u - K.cx) / K.fx, (v - K.cy) / K.fy, 1.0])
    return out


@pytest.mark.parametrize("z", [0.4, 1.2])
def test_the_depth_error_has_sigma_a_plus_b_d2_along_the_ray(z):
    depth = np.full((K.height, K.width), z)
    noisy, _ = apply_depth_noise(SIGMA_ONLY, depth, K, true_pose(), 0, 1, np.random.default_rng(1))
    s = stretch()
    ray_error = (noisy - depth) * s  # the error along each pixel's ray
    normalised = ray_error / (SIGMA_ONLY.sigma_a + SIGMA_ONLY.sigma_b * (z * s) ** 2)
    # 49,152 pixels: the standard error of the std is ~0.3 %, of the mean ~0.005: tolerances 2 % and 0.02
    assert abs(normalised.std() - 1.0) < 0.02 and abs(normalised.mean()) < 0.02
    centre = s < 1.01  # near the optical axis the ray is z: sigma(z) = a + b z^2 within 2 % (~2,800 pixels)
    expected = SIGMA_ONLY.sigma_a + SIGMA_ONLY.sigma_b * z ** 2
    assert abs((noisy - depth)[centre].std() / expected - 1.0) < 0.06


def test_dropouts_remove_their_share_and_no_return_stays():
    profile = NoiseProfile(dropout=0.03)
    depth = np.full((K.height, K.width), 0.5)
    depth[:10] = 0.0
    depth[10:20] = np.nan
    noisy, pose = apply_depth_noise(profile, depth, K, true_pose(), 0, 1, np.random.default_rng(2))
    assert np.all(noisy[:10] == 0.0) and np.all(np.isnan(noisy[10:20]))
    valid = noisy[20:]
    share = float((valid == 0.0).mean())
    n = valid.size
    assert abs(share - 0.03) < 4 * np.sqrt(0.03 * 0.97 / n)  # 4 standard errors
    assert np.all(valid[valid != 0.0] == 0.5)  # no other error
    np.testing.assert_array_equal(pose, true_pose())  # no pose error in this profile


def test_quantisation_puts_every_depth_on_the_grid():
    rng = np.random.default_rng(3)
    depth = rng.uniform(0.3, 0.7, (K.height, K.width))
    noisy, _ = apply_depth_noise(ARM_RGBD, depth, K, true_pose(), 0, 1, np.random.default_rng(4))
    returned = noisy[noisy > 0]
    steps = returned / ARM_RGBD.quantisation
    assert returned.size > 0.98 * depth.size
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-6)
    exact = NoiseProfile(quantisation=0.001)  # alone: the nearest grid depth
    grid, _ = apply_depth_noise(exact, depth, K, true_pose(), 0, 1, np.random.default_rng(0))
    np.testing.assert_allclose(grid, np.round(depth / 0.001) * 0.001, atol=1e-12)


def test_mixed_pixels_lie_between_the_neighbouring_depths_at_edges_only():
    depth = np.full((K.height, K.width), 0.6)
    depth[40:120, 60:180] = 0.3  # a foreground square
    depth[150:, :] = 0.0  # no return: never a neighbour, never moved
    profile = NoiseProfile(mixed_pixels=0.5)
    noisy, _ = apply_depth_noise(profile, depth, K, true_pose(), 0, 1, np.random.default_rng(5))
    edge = np.zeros(depth.shape, dtype=bool)  # brute force: a 3 x 3 window with a step over edge_jump
    lo, hi = np.zeros(depth.shape), np.zeros(depth.shape)
    for v in range(K.height):
        for u in range(K.width):
            if depth[v, u] <= 0:
                continue
            window = depth[max(v - 1, 0):v + 2, max(u - 1, 0):u + 2]
            window = window[window > 0]
            lo[v, u], hi[v, u] = window.min(), window.max()
            edge[v, u] = hi[v, u] - lo[v, u] > profile.edge_jump
    moved = noisy != depth
    assert not moved[~edge].any()
    assert np.all((noisy[moved] >= lo[moved]) & (noisy[moved] <= hi[moved]))
    n = int(edge.sum())
    assert n > 500 and abs(moved[edge].mean() - 0.5) < 4 * np.sqrt(0.25 / n)
    assert noisy[moved].std() > 0.05  # spread between the two depths, not snapped to one


def test_the_reported_pose_is_the_true_pose_times_pose_errors_draw():
    pose = true_pose()
    depth = np.full((K.height, K.width), 0.5)
    for capture in (0, 60, 119):
        _, reported = apply_depth_noise(PHONE_LIDAR, depth, K, pose, capture, 120, np.random.default_rng(7),
                                        drift_seed=11)
        rotation, translation = pose_error(PHONE_LIDAR, capture, 120, np.random.default_rng(7), drift_seed=11)
        np.testing.assert_allclose(reported[:3, :3], rotation @ pose[:3, :3], atol=1e-15)
        np.testing.assert_allclose(reported[:3, 3], pose[:3, 3] + translation, atol=1e-15)
        np.testing.assert_array_equal(reported[3], [0, 0, 0, 1])
        # a point seen in the image lands where apply_noise's pose error puts it: c + t + R (p - c)
        p_cam = np.array([0.05, -0.02, 0.5])
        truth = pose[:3, :3] @ p_cam + pose[:3, 3]
        np.testing.assert_allclose(reported[:3, :3] @ p_cam + reported[:3, 3],
                                   pose[:3, 3] + translation + rotation @ (truth - pose[:3, 3]), atol=1e-12)
    first = apply_depth_noise(PHONE_LIDAR, depth, K, pose, 0, 120, np.random.default_rng(7), drift_seed=11)[1]
    last = apply_depth_noise(PHONE_LIDAR, depth, K, pose, 119, 120, np.random.default_rng(7), drift_seed=11)[1]
    # the same jitter draw: the difference is the full drift, 5 mm
    assert abs(np.linalg.norm(last[:3, 3] - first[:3, 3]) - PHONE_LIDAR.drift_m) < 1e-12


def test_the_same_seed_gives_the_same_noise_and_another_seed_another():
    depth = np.random.default_rng(0).uniform(0.3, 0.7, (K.height, K.width))
    a = apply_depth_noise(PHONE_LIDAR, depth, K, true_pose(), 3, 10, np.random.default_rng([1, 3]), drift_seed=1)
    b = apply_depth_noise(PHONE_LIDAR, depth, K, true_pose(), 3, 10, np.random.default_rng([1, 3]), drift_seed=1)
    c = apply_depth_noise(PHONE_LIDAR, depth, K, true_pose(), 3, 10, np.random.default_rng([2, 3]), drift_seed=1)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    assert not np.array_equal(a[0], c[0]) and not np.array_equal(a[1], c[1])


def test_ideal_returns_its_inputs_and_draws_nothing():
    depth = np.random.default_rng(0).uniform(0.3, 0.7, (K.height, K.width)).astype(np.float32)
    pose = true_pose()
    rng = np.random.default_rng(9)
    state = rng.bit_generator.state
    out, reported = apply_depth_noise(IDEAL, depth, K, pose, 0, 1, rng)
    assert out is depth and reported is pose and rng.bit_generator.state == state


@pytest.fixture(scope="module")
def small_plant():
    scene = plant_scene("tomato", 0, size=0.4, frames=6)
    return scene, render(scene, progress=False)[0]


def test_the_standin_noises_every_frame_from_seed_and_index(small_plant):
    scene, frames = small_plant
    assert noisy_frames(frames, scene.intrinsics, "ideal", 4) == frames
    noisy = noisy_frames(frames, scene.intrinsics, "phone-lidar", 4)
    for i, ((pose, depth, colour), (n_pose, n_depth, n_colour)) in enumerate(zip(frames, noisy)):
        want = apply_depth_noise(PHONE_LIDAR, depth, scene.intrinsics, pose, i, len(frames),
                                 np.random.default_rng([4, i]), drift_seed=4)
        np.testing.assert_array_equal(n_depth, want[0])
        np.testing.assert_array_equal(n_pose, want[1])
        assert n_colour is colour


def test_capture_standin_writes_the_reported_poses(small_plant, tmp_path, capsys):
    scene, frames = small_plant
    out = tmp_path / "noisy"
    assert cli.main(["capture", "standin", "--format", "depth", "--output", str(out), "--frames", "6",
                     "--noise", "phone-lidar", "--noise-seed", "4"]) == 0
    assert "noise phone-lidar" in capsys.readouterr().out
    capture = read_capture(out)
    noisy = noisy_frames(frames, scene.intrinsics, "phone-lidar", 4)
    for frame, (pose, depth, _) in zip(capture.frames, noisy):
        np.testing.assert_allclose(frame.camera_to_world, pose, atol=1e-12)
        written, _ = load_depth(frame)  # the depth PNG: the noisy depth in whole millimetres
        np.testing.assert_allclose(np.nan_to_num(written), np.rint(np.nan_to_num(depth) * 1000) / 1000, atol=1e-9)


def test_capture_standin_refuses_an_unknown_profile_with_one_line(tmp_path, capsys):
    out = tmp_path / "never"
    assert cli.main(["capture", "standin", "--format", "depth", "--output", str(out), "--noise", "phony"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "'phony'" in err and all(name in err for name in ("ideal", "arm-rgbd", "phone-lidar"))
    assert not out.exists()


def test_the_stand_in_robot_camera_s_depth_images_carry_the_sensor_s_depth_errors():
    """tpvp's stand-in camera (a session's robot in the tutorials and tests): ``ideal`` is today's exact
    image; ``phone-lidar`` is that image through apply_depth_noise, seeded by (seed, view, capture), in metres."""
    from tpvp.config_loading import make_config
    from tpvp.scene.samples import load_sample
    from tpvp.simulate.robot_camera import StandInCamera

    pair = load_sample("tomato_0305"), load_sample("tomato_0306")
    exact = StandInCamera(*pair, make_config("plant")).depth(17)
    camera = StandInCamera(*pair, make_config("plant", {"sensor.noise": "phone-lidar"}))
    noisy, again, later = camera.depth(17), camera.depth(17), camera.depth(17, capture=1)
    assert np.array_equal(noisy, again, equal_nan=True) and not np.array_equal(noisy, later, equal_nan=True)
    seen = np.isfinite(exact)
    assert seen.any() and not np.isfinite(noisy[~seen]).any()  # no return stays no return (mixed pixels need one)
    scene = camera.scene
    metres = np.where(seen, exact * scene.scan_scale / scene.per_metre, 0.0)
    expected, _ = apply_depth_noise(PHONE_LIDAR, metres, camera.scene.sensor.intrinsics, np.eye(4), 0,
                                    len(scene.view_space), np.random.default_rng([scene.seed, 17, 0]),
                                    drift_seed=scene.seed)
    expected = expected * scene.per_metre / scene.scan_scale
    expected[~(expected > 0)] = np.nan
    np.testing.assert_allclose(noisy, expected, rtol=1e-12, equal_nan=True)
    dropped = seen & ~np.isfinite(noisy)
    assert 0.5 * PHONE_LIDAR.dropout < dropped.sum() / seen.sum() < 3 * PHONE_LIDAR.dropout
