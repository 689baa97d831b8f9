"""A greenhouse row's passive sweep through the sensor's noise profile (``sensor.noise``,
docs/sensor.md#sensor-noise): each of the 15 passive views' captures is noisy, Q and its cameras are
fused from them as a row session fuses its captures; the ground truth, the oracle and every coverage
stay exact; ``ideal`` is today's exact sweep bit for bit; a session fed by the stand-in camera plans
the simulator's plan under a noisy profile too."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from tpvp.errors import ConfigError
from tpvp.sensor.noise import noise_profile
from tpvp.simulate.greenhouse import (build_row_scene, execute, observed_points, passive_reconstruction,
                                      row_coverage, run_row_case)
from tpvp.simulate.robot_camera import RowStandInCamera
from tpvp.simulate.row_cases import RowCase, quick_config

FAST = {"view_space": "room1", "targets.rounds": 2}


@pytest.fixture(scope="module")
def pair():
    return RowCase("room1", 0, 0).load()


@pytest.fixture(scope="module")
def oracles(tmp_path_factory):
    return tmp_path_factory.mktemp("oracles")


@pytest.fixture(scope="module")
def exact(pair, oracles):
    return build_row_scene(*pair, quick_config(FAST), cache_dir=oracles)


@pytest.fixture(scope="module")
def phone(pair, oracles):
    return build_row_scene(*pair, quick_config({**FAST, "sensor.noise": "phone-lidar"}), cache_dir=oracles)


def test_the_ideal_sensor_is_todays_exact_sweep(pair, oracles, exact):
    ideal = build_row_scene(*pair, quick_config({**FAST, "sensor.noise": "ideal"}), cache_dir=oracles)
    assert np.array_equal(ideal.coarse, exact.coarse)
    assert np.array_equal(ideal.known.passive_cameras, exact.known.passive_cameras)
    # The noisy path's fusion of exact captures is today's Q too: one point per voxel, the first view's.
    room, config = exact.room, quick_config(FAST)
    observed = observed_points(exact.grid, exact.current)
    captures = [(v, observed[np.sort(exact.passive_visibility[v].indices)]) for v in range(len(room.initial_positions))]
    coarse, first = passive_reconstruction(captures, config.gt_resolution)
    assert np.array_equal(coarse, exact.coarse)
    assert np.array_equal(room.initial_positions[first], exact.known.passive_cameras)


def test_a_noisy_sweep_moves_q_near_the_truth_and_leaves_the_truth_exact(exact, phone):
    assert phone.coarse.shape != exact.coarse.shape or not np.array_equal(phone.coarse, exact.coarse)
    cameras = phone.known.passive_cameras
    assert len(cameras) == len(phone.coarse)
    assert all(any(np.array_equal(c, p) for p in phone.room.initial_positions) for c in np.unique(cameras, axis=0))
    # Measured on this case (2 cm voxels, views 0.7-1.4 m from the points): the mean distance from Q to
    # the nearest ground-truth voxel centre is 8.5 mm exact and 16.7 mm under phone-lidar, whose depth
    # sigma averages 9.2 mm over Q's depths (pose jitter and drift and mixed pixels come on top).
    centres = cKDTree(exact.grid.centres)
    noisy, clean = centres.query(phone.coarse)[0].mean(), centres.query(exact.coarse)[0].mean()
    sigma = noise_profile("phone-lidar").sigma(np.linalg.norm(phone.coarse - cameras, axis=1)).mean()
    assert clean < noisy < clean + 3 * sigma
    # The ground truth, its oracle and what the sweep truly saw do not move.
    assert np.array_equal(phone.grid.keys, exact.grid.keys)
    assert np.array_equal(phone.oracle, exact.oracle)
    assert np.array_equal(phone.passive_seen, exact.passive_seen)
    assert (phone.passive_visibility != exact.passive_visibility).nnz == 0


def test_the_noise_is_drawn_from_the_seed(pair, oracles, phone):
    again = build_row_scene(*pair, quick_config({**FAST, "sensor.noise": "phone-lidar"}), cache_dir=oracles)
    assert np.array_equal(again.coarse, phone.coarse)
    assert np.array_equal(again.known.passive_cameras, phone.known.passive_cameras)
    other = build_row_scene(*pair, quick_config({**FAST, "sensor.noise": "phone-lidar", "seed": 1}), cache_dir=oracles)
    assert other.coarse.shape != phone.coarse.shape or not np.array_equal(other.coarse, phone.coarse)


def test_a_noisy_sweep_still_plans_and_its_coverage_is_measured_on_the_truth(exact, phone):
    config = quick_config({**FAST, "sensor.noise": "phone-lidar"})
    result = run_row_case(phone, config)
    assert result.n_views > len(phone.room.initial_positions) and len(result.planned_views) > 0
    assert 0.0 < result.coverage <= 1.0 and np.isfinite(result.path_length)
    # The coverage is the exact truth's: the same views executed on the exact scene cover the same.
    assert result.coverage == row_coverage(exact, execute(exact, result.positions, result.look_ats))
    assert result.coverage_captured == row_coverage(exact, [])


@pytest.mark.slow
def test_a_noisy_row_session_plans_what_the_simulator_plans(tmp_path, pair, oracles):
    from tpvp.session import Session

    config = quick_config({**FAST, "sensor.noise": "phone-lidar"})
    camera = RowStandInCamera(*pair, config, cache_dir=oracles)
    simulated = run_row_case(camera.scene, config)
    session = Session.start(tmp_path / "session", pair[0], config, "generated room1 row, session 0")
    while (request := session.request()).view is not None:
        session.add(camera.cloud(request.position, request.look_at), request.view, "cloud")
    known = session.known()
    assert np.array_equal(known.coarse, camera.scene.coarse)
    assert np.array_equal(known.passive_cameras, camera.scene.known.passive_cameras)
    planned = session.plan()
    assert np.array_equal(planned.positions, simulated.positions)
    assert np.array_equal(planned.look_ats, simulated.look_ats)
    assert abs(planned.path_length - simulated.path_length) <= 1e-9


def test_the_stand_in_camera_seeds_a_pose_off_the_sweep_by_its_view(pair, oracles):
    config = quick_config({**FAST, "sensor.noise": "phone-lidar"})
    camera = RowStandInCamera(*pair, config, cache_dir=oracles)
    room = camera.scene.room
    position, look_at = room.initial_positions[3] + [0.0, 0.05, 0.0], room.initial_look_ats[3]
    with pytest.raises(ConfigError, match="view index"):
        camera.cloud(position, look_at)
    first, again = camera.cloud(position, look_at, view=20), camera.cloud(position, look_at, view=20)
    assert np.array_equal(first, again) and not np.array_equal(first, camera.cloud(position, look_at, view=21))
    # A passive pose is recognised: its view and capture are its place in the sweep.
    assert np.array_equal(camera.cloud(room.initial_positions[3], look_at),
                          camera.cloud(room.initial_positions[3], look_at, view=3, capture=3))
