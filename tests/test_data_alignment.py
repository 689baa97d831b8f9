"""Landmark-guided ICP (data_tools.alignment): Kabsch against scipy, landmark files, recovery of a
known rigid offset on the generated greenhouse stand-in."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from data_tools.alignment import (
    IcpConfig,
    align_to_reference,
    landmark_transform,
    read_landmarks,
    rigid_from_pairs,
    rotation_angle_deg,
    transform_points,
)
from data_tools.errors import ConfigError, InputFileError, PointCloudError
from data_tools.greenhouse_standin import session_offset
from tpvp.io import read_point_cloud
from tpvp.scene.boxes import room_config


def random_transform(rng) -> np.ndarray:
    transform = np.eye(4)
    transform[:3, :3] = Rotation.random(random_state=rng.integers(1 << 31)).as_matrix()
    transform[:3, 3] = rng.uniform(-2, 2, 3)
    return transform


def alignment_error(estimate: np.ndarray, truth: np.ndarray, box) -> tuple[float, float]:
    """(largest displacement (m) of the plant-box corners, rotation error (deg)) of estimate vs truth."""
    corners = box.corners()
    moved = np.abs(transform_points(corners, estimate) - transform_points(corners, truth))
    return float(np.linalg.norm(moved, axis=1).max()), rotation_angle_deg(estimate[:3, :3] @ truth[:3, :3].T)


def test_rigid_from_pairs_matches_scipy_and_recovers_exact_transform():
    rng = np.random.default_rng(1)
    for _ in range(5):
        truth = random_transform(rng)
        source = rng.uniform(-1, 1, (8, 3))
        target = transform_points(source, truth)
        estimate = rigid_from_pairs(source, target)
        np.testing.assert_allclose(estimate, truth, atol=1e-9)
        # Noisy pairs: the least-squares rotation equals scipy's (Kabsch / Wahba) solution.
        noisy = target + rng.normal(0, 0.01, target.shape)
        estimate = rigid_from_pairs(source, noisy)
        reference, _ = Rotation.align_vectors(noisy - noisy.mean(0), source - source.mean(0))
        np.testing.assert_allclose(estimate[:3, :3], reference.as_matrix(), atol=1e-9)


def test_rigid_from_pairs_never_reflects_planar_points():
    rng = np.random.default_rng(2)
    source = np.column_stack([rng.uniform(-1, 1, (6, 2)), np.zeros(6)])
    truth = random_transform(rng)
    estimate = rigid_from_pairs(source, transform_points(source, truth))
    assert np.linalg.det(estimate[:3, :3]) == pytest.approx(1.0)
    np.testing.assert_allclose(estimate, truth, atol=1e-9)


@pytest.mark.parametrize("source, match", [
    (np.array([[0.0, 0, 0], [1, 0, 0]]), "at least 3"),
    (np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 1e-7]]), "collinear"),
])
def test_rigid_from_pairs_rejects_degenerate_landmarks(source, match):
    with pytest.raises(ConfigError, match=match):
        rigid_from_pairs(source, source)


HEADER = "source_x,source_y,source_z,target_x,target_y,target_z\n"


def test_read_landmarks_with_header_comments_and_permuted_columns(tmp_path):
    pairs = np.arange(24, dtype=float).reshape(4, 6) ** 1.5
    plain = tmp_path / "plain.csv"
    plain.write_text("# picked in CloudCompare\n" + "\n".join(" ".join(map(str, r)) for r in pairs) + "\n")
    permuted = tmp_path / "permuted.csv"
    order = ["target_x", "target_y", "target_z", "source_x", "source_y", "source_z"]
    permuted.write_text(",".join(order) + "\n" + "\n".join(
        ",".join(map(str, np.r_[r[3:], r[:3]])) + "  # post " + str(i) for i, r in enumerate(pairs)))
    for path in (plain, permuted):
        source, target = read_landmarks(path)
        np.testing.assert_array_equal(source, pairs[:, :3])
        np.testing.assert_array_equal(target, pairs[:, 3:])


@pytest.mark.parametrize("text, match", [
    (HEADER + "0,0,0,0,0,0\n1,0,0,1,0,0\n", "2 landmark pair(s), at least 3"),
    ("", "empty file"),
    (HEADER, "0 landmark pair(s), at least 3"),
    ("source_x,source_y,target_x\n", "lacks source_z, target_y, target_z"),
    (HEADER + "0,0,0,0,0,0\n1,0,nan,1,0,0\n0,1,0,0,1,0\n", "NaN"),
    ("0 0 0 0 0\n1 0 0 1 0\n0 1 0 0 1\n", "6 numbers"),
    (HEADER + "0,0,0,0,0,0\n1,0,0,1,0,0\n2,0,0,2,0,0\n", "collinear"),
    (HEADER + "0,0,zero,0,0,0\n", "line 2: non-numeric value 'zero'"),
])
def test_bad_landmark_files_give_one_line_error_naming_the_file(tmp_path, text, match):
    path = tmp_path / "room1_20250918.csv"
    path.write_text(text)
    with pytest.raises(InputFileError) as info:
        landmark_transform(path)
    message = str(info.value)
    assert str(path) in message and match in message and "\n" not in message


def test_missing_landmarks_file(tmp_path):
    with pytest.raises(InputFileError, match="none.csv: file not found"):
        read_landmarks(tmp_path / "none.csv")


@pytest.fixture(scope="module")
def standin(raw_standin):
    return raw_standin


@pytest.mark.parametrize("date", ["20250918", "20250922"])
def test_known_rigid_offset_is_recovered_within_5mm_and_half_a_degree(standin, date):
    box = room_config("room1").plant_box
    reference = read_point_cloud(standin.scans["20250915"], units="m")
    scan = read_point_cloud(standin.scans[date], units="m")
    result = align_to_reference(scan, reference, landmarks=standin.landmarks[date], plant_box=box)
    truth = np.linalg.inv(standin.offsets[date])
    displacement, angle = alignment_error(result.transform, truth, box)
    assert result.method == "landmarks+icp(static)"
    assert displacement < 0.005 and angle < 0.5, (displacement, angle)
    assert result.fitness > 0.9 and result.inlier_rmse < 0.015
    # The landmarks alone (2 mm picking noise) are already close; ICP must not make it worse.
    landmarks_only, residual = landmark_transform(standin.landmarks[date])
    assert residual < 0.005
    assert displacement <= alignment_error(landmarks_only, truth, box)[0] + 1e-3


def test_far_offset_without_landmarks_is_refused(standin):
    reference = read_point_cloud(standin.scans["20250915"], units="m")
    scan = read_point_cloud(standin.scans["20250918"], units="m")
    assert np.linalg.norm(session_offset(1)[:3, 3]) > 0.1
    with pytest.raises(PointCloudError, match="landmarks file"):
        align_to_reference(scan, reference, plant_box=room_config("room1").plant_box)


def test_cropped_models_without_landmarks_keep_their_frame():
    """Already aligned processed models (plants only) are not pulled by ICP onto the other day."""
    box = room_config("room1").plant_box
    rng = np.random.default_rng(0)
    reference = box.sample_uniform(3000, rng)
    scan = box.sample_uniform(3000, rng)
    result = align_to_reference(scan, reference, plant_box=box, config=IcpConfig(voxel_size=0.05))
    np.testing.assert_array_equal(result.transform, np.eye(4))
    assert result.method == "identity" and 0 < result.fitness <= 1
