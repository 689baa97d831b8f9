"""Capture import: the stand-in phone's captures in each layout read back with the poses they were
rendered at (camera conventions), fused within the target of the generated truth, the support
check against a brute force, and every kind of bad input refused with one line, nothing written."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from data_tools import cli
from data_tools.capture.formats import FORMATS, depth_intrinsics, read_capture
from data_tools.capture.fusion import fuse, fusion_config, supported
from data_tools.capture.standin import plant_scene, write_standin
from tpvp.io import read_point_cloud
from tpvp.metrics.geometry import chamfer_distance
from tpvp.sensor.camera import Intrinsics, switch_camera_axes

FRAMES = 48


@pytest.fixture(scope="module")
def scene():
    return plant_scene("tomato", 0, size=0.4, frames=FRAMES)


@pytest.fixture(scope="module")
def captures(scene, tmp_path_factory):
    """The stand-in plant in every layout (read-only for the tests that share it)."""
    root = tmp_path_factory.mktemp("captures")
    return {fmt: write_standin(root / fmt, fmt, scene, progress=False) for fmt in FORMATS}


@pytest.fixture(scope="module")
def truth(captures):
    return read_point_cloud(captures["depth"] / "truth.ply", units="m")


def copy(captures, fmt, tmp_path) -> Path:
    return Path(shutil.copytree(captures[fmt], tmp_path / fmt))


@pytest.mark.parametrize("fmt", FORMATS)
def test_every_layout_reads_back_the_poses_it_was_rendered_at(fmt, scene, captures):
    capture = read_capture(captures[fmt])
    assert capture.format == fmt and len(capture.frames) == FRAMES
    for frame, position, look_at in zip(capture.frames, scene.positions, scene.look_ats):
        pose = frame.camera_to_world
        np.testing.assert_allclose(pose[:3, 3], position, atol=1e-12)
        # OpenCV axes: the camera's z axis looks at the plant, its y axis points down (world -z side)
        forward = (look_at - position) / np.linalg.norm(look_at - position)
        np.testing.assert_allclose(pose[:3, 2], forward, atol=1e-9)
        assert pose[2, 1] < 0
        k = scene.intrinsics
        assert depth_intrinsics(frame, (k.height, k.width)) == k  # the colour's intrinsics, scaled


def test_the_fused_plant_lies_within_2_mm_of_the_truth_in_every_layout(captures, truth):
    fused = {fmt: fuse(read_capture(captures[fmt]), fusion_config("plant"), progress=False) for fmt in FORMATS}
    points, colours = fused["nerfstudio"]
    assert chamfer_distance(points, truth) <= 0.002
    assert colours.dtype == np.uint8 and colours.shape == points.shape
    for fmt in ("polycam", "depth"):  # one capture, three layouts: the same cloud
        assert len(fused[fmt][0]) == len(points)
        np.testing.assert_allclose(fused[fmt][0], points, atol=1e-6)


def test_a_flipped_camera_axis_cannot_pass(captures, truth, tmp_path):
    folder = copy(captures, "nerfstudio", tmp_path)
    transforms = json.loads((folder / "transforms.json").read_text())
    for frame in transforms["frames"]:  # OpenCV axes written where nerfstudio expects OpenGL's
        frame["transform_matrix"] = switch_camera_axes(frame["transform_matrix"]).tolist()
    (folder / "transforms.json").write_text(json.dumps(transforms))
    points, _ = fuse(read_capture(folder), fusion_config("plant"), progress=False)
    assert chamfer_distance(points, truth) > 0.1  # the cameras looked away: the clutter of their backs


def test_a_polycam_capture_keeps_arkits_y_up_world_turned_z_up(captures, scene):
    camera = sorted((captures["polycam"] / "keyframes" / "cameras").glob("*.json"))[0]
    data = json.loads(camera.read_text())
    # ARKit's y axis is up: the camera's height above the plant base is its t_13
    assert data["t_13"] == pytest.approx(scene.positions[0][2], abs=1e-12)


def test_the_support_check_equals_a_brute_force():
    rng = np.random.default_rng(3)
    k = Intrinsics(fx=8.0, fy=8.0, cx=4.0, cy=3.0, width=8, height=6)
    poses = []
    for _ in range(3):
        pose = np.eye(4)
        pose[:3, :3] = np.linalg.qr(rng.normal(size=(3, 3)))[0] * [1, 1, 1]
        if np.linalg.det(pose[:3, :3]) < 0:
            pose[:3, 0] *= -1
        pose[:3, 3] = rng.normal(size=3) * 0.1
        poses.append(pose)
    measured = [(np.where(rng.random((6, 8)) < 0.8, rng.uniform(0.5, 1.5, (6, 8)), 0).astype(np.float32), k)
                for _ in poses]
    points = rng.normal(size=(400, 3))
    tolerance = 0.3
    expected = np.zeros(len(points), dtype=bool)
    for i, p in enumerate(points):
        for pose, (depth, kk) in zip(poses, measured):
            x, y, z = np.linalg.inv(pose)[:3] @ np.append(p, 1.0)
            if z <= 0:
                continue
            u, v = round(kk.fx * x / z + kk.cx), round(kk.fy * y / z + kk.cy)
            if 0 <= u < kk.width and 0 <= v < kk.height and depth[v, u] > 0 and abs(depth[v, u] - z) <= tolerance:
                expected[i] = True
    assert expected.any() and not expected.all()
    np.testing.assert_array_equal(supported(points, poses, measured, tolerance), expected)


def test_capture_commands_write_a_standin_and_fuse_it(tmp_path, capsys, truth):
    standin = tmp_path / "phone"
    assert cli.main(["capture", "standin", "--format", "polycam", "--output", str(standin), "--frames", "24"]) == 0
    assert (standin / "keyframes" / "cameras").is_dir() and (standin / "truth.ply").is_file()
    assert cli.main(["capture", "standin", "--format", "polycam", "--output", str(standin)]) == 2
    assert "pass --force" in capsys.readouterr().err
    cloud = tmp_path / "cloud.ply"
    assert cli.main(["capture", "fuse", str(standin), "--output", str(cloud)]) == 0
    assert "24 frames (polycam)" in capsys.readouterr().out
    assert chamfer_distance(read_point_cloud(cloud, units="m"), truth) < 0.004


def _empty(folder: Path) -> str:
    shutil.rmtree(folder)
    folder.mkdir()
    return "is empty"


def _unknown(folder: Path) -> str:
    shutil.rmtree(folder)
    folder.mkdir()
    (folder / "scan.mov").write_bytes(b"\0")
    return "cannot tell the capture's format"


def _missing_depth(folder: Path) -> str:
    depth = sorted((folder / "keyframes" / "depth").glob("*.png"))[5]
    depth.unlink()
    return f"{depth.name}: missing"


def _missing_image(folder: Path) -> str:
    (folder / "images" / "frame_00003.png").unlink()
    return "frame_00003.png: missing"


def _not_rigid(folder: Path) -> str:
    pose = folder / "poses" / "000002.txt"
    matrix = np.loadtxt(pose)
    matrix[:3, :3] *= 1.2  # a scaled pose
    np.savetxt(pose, matrix)
    return "frame 000002's pose is not a rigid transform"


def _wrong_size(folder: Path) -> str:
    intrinsics = folder / "intrinsics.yaml"
    intrinsics.write_text(intrinsics.read_text().replace("width: 256", "width: 320"))
    return "the depth image is 256 x 192 pixels but the intrinsics say 320 x 192"


BAD = {"empty-folder": ("depth", _empty, []), "unknown-format": ("depth", _unknown, []),
       "missing-depth": ("polycam", _missing_depth, []), "missing-image": ("nerfstudio", _missing_image, []),
       "not-rigid": ("depth", _not_rigid, []), "wrong-size": ("depth", _wrong_size, []),
       "wrong-units": ("polycam", lambda folder: "try --depth-scale 0.001", ["--depth-scale", "1"])}


@pytest.mark.parametrize("case", BAD)
def test_bad_capture_is_one_line_and_writes_nothing(case, captures, tmp_path, capsys):
    fmt, damage, options = BAD[case]
    folder = copy(captures, fmt, tmp_path)
    expected = damage(folder)
    output = tmp_path / "cloud.ply"
    code = cli.main(["capture", "fuse", str(folder), "--output", str(output), *options])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1, err
    assert expected in err and "Traceback" not in err
    assert not output.exists() and not list(tmp_path.glob("cloud*"))
