"""The sensor's noise profiles (tpvp/sensor/noise.py, ``sensor.noise``): figures measured by brute
force on many points, determinism, the ideal sensor bit for bit, and the simulator's captures."""

import math
from dataclasses import replace

import numpy as np
import pytest

from tpvp.config_loading import config_yaml, make_config
from tpvp.errors import ConfigError
from tpvp.sensor.noise import NOISE_PROFILES, apply_noise, drift_directions, noise_profile, pose_error

NOISY = ("arm-rgbd", "phone-lidar")


def depth_only(profile):
    """The profile without its pose error (the depth errors alone)."""
    return replace(profile, jitter_m=0.0, jitter_deg=0.0, drift_m=0.0, drift_deg=0.0)


def shell(n: int, radius: float, seed: int = 0) -> np.ndarray:
    """``n`` points on a sphere of ``radius`` around the origin: every depth equal, so no depth edge."""
    directions = np.random.default_rng(seed).standard_normal((n, 3))
    return radius * directions / np.linalg.norm(directions, axis=1, keepdims=True)


def test_the_three_profiles_are_registered_and_ideal_is_the_default():
    assert NOISE_PROFILES.names() == ["arm-rgbd", "ideal", "phone-lidar"]
    assert make_config("plant").sensor.noise == "ideal" and make_config("row").sensor.noise == "ideal"
    assert noise_profile("ideal").ideal and not any(noise_profile(name).ideal for name in NOISY)
    phone = noise_profile("phone-lidar")
    assert (phone.sigma_a, phone.sigma_b, phone.dropout) == (0.002, 0.006, 0.03)
    assert (phone.jitter_m, phone.jitter_deg, phone.drift_m, phone.drift_deg) == (0.002, 0.2, 0.005, 0.5)
    arm = noise_profile("arm-rgbd")
    assert (arm.jitter_m, arm.jitter_deg, arm.drift_m, arm.drift_deg) == (0.001, 0.1, 0.0, 0.0)


def test_ideal_returns_the_input_itself_and_draws_nothing():
    points = shell(1000, 0.5)
    rng = np.random.default_rng(3)
    state = rng.bit_generator.state
    assert apply_noise(noise_profile("ideal"), points, np.zeros(3), 4, 10, rng) is points
    assert rng.bit_generator.state == state


@pytest.mark.parametrize("name", NOISY)
def test_depth_sigma_is_a_plus_b_d_squared(name):
    """Brute force: the empirical std of the along-ray error of 200,000 points at 0.3 m and at 0.7 m
    is the profile's a + b d^2 within 2 % (the standard error of a std over 200,000 draws is 0.16 %;
    quantisation adds step^2/12, under 0.1 % here)."""
    profile = replace(depth_only(noise_profile(name)), dropout=0.0)
    camera = np.array([0.1, -0.2, 0.3])
    for distance in (0.3, 0.7):
        points = camera + shell(200_000, distance)
        noisy = apply_noise(profile, points, camera, 0, 1, np.random.default_rng([7, int(distance * 10)]))
        error = np.linalg.norm(noisy - camera, axis=1) - distance
        expected = profile.sigma_a + profile.sigma_b * distance ** 2
        assert error.std() == pytest.approx(expected, rel=0.02)
        assert abs(error.mean()) < 0.05 * expected  # unbiased
        # along the ray: the direction from the camera is kept
        directions = (noisy - camera) / np.linalg.norm(noisy - camera, axis=1, keepdims=True)
        assert np.allclose(directions, (points - camera) / distance, atol=1e-12)


@pytest.mark.parametrize("name", NOISY)
def test_dropout_share(name):
    profile = depth_only(noise_profile(name))
    n = 200_000
    kept = len(apply_noise(profile, shell(n, 0.5), np.zeros(3), 0, 1, np.random.default_rng(11)))
    tolerance = 4 * math.sqrt(profile.dropout * (1 - profile.dropout) / n)  # 4 binomial standard errors
    assert 1 - kept / n == pytest.approx(profile.dropout, abs=tolerance)


def test_quantisation_puts_depths_on_the_grid():
    profile = depth_only(noise_profile("arm-rgbd"))
    assert profile.quantisation == 0.0001
    camera = np.array([0.0, 0.0, 0.5])
    for points in (camera + shell(5000, 0.42), two_planes(camera)):  # two_planes: mixed pixels too
        depth = np.linalg.norm(apply_noise(profile, points, camera, 0, 1, np.random.default_rng(5)) - camera, axis=1)
        steps = depth / profile.quantisation
        assert np.abs(steps - np.round(steps)).max() < 1e-6
        step = replace(profile, quantisation=0.005)
        depth = np.linalg.norm(apply_noise(step, points, camera, 0, 1, np.random.default_rng(5)) - camera, axis=1)
        assert np.abs(depth / 0.005 - np.round(depth / 0.005)).max() < 1e-6


def two_planes(camera, n: int = 4000) -> np.ndarray:
    """A square patch 0.3 m in front of the camera (looking down -z) over a wider one 0.6 m away:
    a depth edge along the patch's border."""
    rng = np.random.default_rng(2)
    front = np.column_stack([rng.uniform(-0.05, 0.05, (n, 2)), np.full(n, -0.3)])
    back = np.column_stack([rng.uniform(-0.2, 0.2, (n, 2)), np.full(n, -0.6)])
    back = back[(np.abs(back[:, :2]) > 0.1).any(axis=1)]  # the back patch where the front one does not hide it
    return camera + np.vstack([front, back])


def test_mixed_pixels_lie_between_foreground_and_background():
    camera = np.zeros(3)
    points = two_planes(camera)
    depth = np.linalg.norm(points, axis=1)
    profile = replace(depth_only(noise_profile("phone-lidar")), sigma_a=0.0, sigma_b=0.0, dropout=0.0)
    noisy = apply_noise(profile, points, camera, 0, 1, np.random.default_rng(8))
    moved = np.abs(np.linalg.norm(noisy, axis=1) - depth) > 1e-9
    assert 0 < moved.sum() < 0.2 * len(points)  # only points at the border move
    assert (np.linalg.norm(noisy[moved], axis=1) >= 0.3 - 1e-9).all()
    assert (np.linalg.norm(noisy[moved], axis=1) <= np.linalg.norm(points, axis=1).max() + 1e-9).all()
    between = np.linalg.norm(noisy[moved], axis=1)
    assert ((between > 0.35) & (between < 0.55)).any()  # off both surfaces: a flying pixel
    none = apply_noise(replace(profile, mixed_pixels=0.0, quantisation=0.001), points, camera, 0, 1,
                       np.random.default_rng(8))
    assert np.abs(np.linalg.norm(none, axis=1) - depth).max() <= 0.0005 + 1e-12  # quantisation alone


@pytest.mark.parametrize("name", NOISY)
def test_pose_jitter_and_drift_are_as_configured(name):
    profile = noise_profile(name)
    draws = [pose_error(replace(profile, drift_m=0.0, drift_deg=0.0), 0, 1, np.random.default_rng([1, i]))
             for i in range(4000)]
    translation = np.array([np.linalg.norm(t) for _, t in draws])
    angle = np.degrees([math.acos(np.clip((np.trace(r) - 1) / 2, -1, 1)) for r, _ in draws])
    assert math.sqrt(np.mean(translation ** 2)) == pytest.approx(profile.jitter_m, rel=0.05)  # RMS
    assert math.sqrt(np.mean(angle ** 2)) == pytest.approx(profile.jitter_deg, rel=0.05)
    still = replace(profile, jitter_m=0.0, jitter_deg=0.0)
    axis_t, axis_r = drift_directions(4)
    for index, share in ((0, 0.0), (5, 0.5), (10, 1.0)):
        r, t = pose_error(still, index, 11, np.random.default_rng(0), drift_seed=4)
        assert np.linalg.norm(t) == pytest.approx(share * profile.drift_m, abs=1e-15)
        assert np.allclose(t, share * profile.drift_m * axis_t)
        angle = math.degrees(math.acos(np.clip((np.trace(r) - 1) / 2, -1, 1)))
        assert angle == pytest.approx(share * profile.drift_deg, abs=1e-6)
        if profile.drift_deg and share:
            rotvec_axis = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])  # 2 sin(angle) axis
            assert np.allclose(rotvec_axis / np.linalg.norm(rotvec_axis), axis_r)


def test_the_pose_error_moves_the_capture_rigidly_about_the_camera():
    profile = replace(noise_profile("phone-lidar"), sigma_a=0.0, sigma_b=0.0, dropout=0.0, mixed_pixels=0.0)
    camera = np.array([0.4, 0.0, 0.2])
    points = camera + shell(500, 0.4)
    noisy = apply_noise(profile, points, camera, 7, 10, np.random.default_rng([0, 3, 7]), drift_seed=0)
    rng = np.random.default_rng([0, 3, 7])
    rng.standard_normal(len(points)), rng.random(len(points))  # the depth noise's and the dropouts' draws
    r, t = pose_error(profile, 7, 10, rng, drift_seed=0)
    assert np.linalg.norm(t) > 0.0035  # 7/9 of the 5 mm drift, give or take the 2 mm jitter
    assert np.allclose(noisy, camera + t + (points - camera) @ r.T, atol=1e-12)
    assert np.allclose(np.linalg.norm(noisy[:, None] - noisy[None], axis=2),
                       np.linalg.norm(points[:, None] - points[None], axis=2), atol=1e-12)  # distances kept
    scaled = apply_noise(profile, 2 * points, 2 * camera, 7, 10, np.random.default_rng([0, 3, 7]), per_metre=2.0)
    assert np.allclose(scaled, 2 * noisy, atol=1e-12)  # figures in metres, frame in its own units


@pytest.mark.parametrize("name", NOISY)
def test_noise_is_deterministic_given_the_rng(name):
    profile = noise_profile(name)
    points, camera = two_planes(np.zeros(3)), np.zeros(3)
    first = apply_noise(profile, points, camera, 2, 5, np.random.default_rng([0, 1, 2]))
    again = apply_noise(profile, points, camera, 2, 5, np.random.default_rng([0, 1, 2]))
    other = apply_noise(profile, points, camera, 2, 5, np.random.default_rng([1, 1, 2]))
    assert np.array_equal(first, again) and not np.array_equal(first[:100], other[:100])


def test_unknown_profile_is_one_config_error_naming_the_choices():
    with pytest.raises(ConfigError, match=r"'sensor\.noise'.*'lidar'.*arm-rgbd, ideal, phone-lidar"):
        make_config("plant", {"sensor.noise": "lidar"})
    with pytest.raises(ConfigError, match="arm-rgbd, ideal, phone-lidar"):
        noise_profile("lidar")
    with pytest.raises(ConfigError, match="noise"):
        make_config("plant", {"sensor.noise": ""})
    assert "noise: ideal" in config_yaml(make_config("plant"))
    assert make_config("plant", {"sensor.noise": "arm-rgbd"}).sensor.noise == "arm-rgbd"


@pytest.fixture(scope="module")
def maize_pair():
    from tpvp.synthetic.plants import generate_session_pair

    return generate_session_pair("maize", 2, days=2.0)


def test_ideal_scene_observes_exactly_and_plans_as_the_default(maize_pair):
    """The default configuration (no ``sensor.noise`` key) and an explicit ``ideal`` give the exact
    voxel centres (today's observation, bit for bit) and the same plan."""
    from tpvp.simulate.single_plant import build_scene, run_case

    iterations = {"registration.embedded_deformation.iterations": 120}
    default = make_config("plant", iterations)
    ideal = make_config("plant", {**iterations, "sensor.noise": "ideal"})
    scene = build_scene(maize_pair.previous.points, maize_pair.current.points, default)
    scene_ideal = build_scene(maize_pair.previous.points, maize_pair.current.points, ideal)
    for view in (0, default.initial_view, len(scene.view_space) - 1):
        exact = scene.grid.centres[scene.truth_visibility[view].indices]
        assert np.array_equal(scene.observe(view), exact) and np.array_equal(scene.observe(view, 3), exact)
        assert np.array_equal(scene_ideal.observe(view), exact)
    a, b = run_case(scene, default), run_case(scene_ideal, ideal)
    assert (a.executed_views, a.planned_views, a.path_length, a.coverage) == \
        (b.executed_views, b.planned_views, b.path_length, b.coverage)


def test_a_noisy_scene_keeps_the_truth_exact_and_is_seeded(maize_pair):
    from tpvp.simulate.single_plant import build_scene

    config = make_config("plant", {"sensor.noise": "phone-lidar"})
    exact = build_scene(maize_pair.previous.points, maize_pair.current.points, make_config("plant"))
    noisy = build_scene(maize_pair.previous.points, maize_pair.current.points, config)
    assert (exact.truth_visibility != noisy.truth_visibility).nnz == 0 and np.array_equal(exact.oracle, noisy.oracle)
    view = config.initial_view
    truth = exact.observe(view)
    seen = noisy.observe(view)
    assert np.array_equal(seen, noisy.observe(view))  # same seed, view and capture: same noise
    assert not np.array_equal(seen, noisy.observe(view, 1))  # another capture: other noise, more drift
    assert 0.9 * len(truth) < len(seen) < len(truth)  # 3 % dropouts
    other_seed = build_scene(maize_pair.previous.points, maize_pair.current.points,
                             make_config("plant", {"sensor.noise": "phone-lidar", "seed": 1}))
    assert not np.array_equal(seen, other_seed.observe(view))
    offset = np.linalg.norm(seen.mean(axis=0) - truth.mean(axis=0))
    assert 0 < offset < 0.02  # millimetres of error on a 0.24 m plant
