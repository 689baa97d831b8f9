"""Capture import: the stand-in phone's captures in each layout read back with the poses they were
rendered at (camera conventions), fused within the target of the generated truth, the support
check against a brute force, and every kind of bad input refused with one line, nothing written."""

from __future__ import annotations

import dataclasses
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from data_tools import cli
from data_tools.capture.formats import FORMATS, check_frame_name, depth_intrinsics, read_capture
from data_tools.capture.fusion import depth_bounds, frame_depths, frames_needed, fuse, fusion_config, supported
from data_tools.capture.phone_standin import plant_scene, write_standin
from data_tools.errors import ConfigError, InputFileError, PointCloudError
from tpvp.export.images import frame_names
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


def _scale_png(path: Path, factor: float) -> None:
    """The 16-bit depth PNG at ``path`` written in other units: its values times ``factor``."""
    from PIL import Image

    with Image.open(path) as image:
        depth = np.asarray(image).astype(np.float64)
    Image.fromarray(np.clip(np.rint(depth * factor), 0, 65535).astype(np.uint16)).save(path)


def _units_middle_frame(folder: Path) -> str:
    _scale_png(folder / "depth" / "000023.png", 10)  # 0.1 mm units in one frame of millimetre ones
    return ("000023.png: frame 000023's depth lies 4.", "m away (its nearest tenth) read at 0.001 m per unit, outside "
            "the 0.1-1.5 m these settings fuse (20 voxels to --max-depth), while 47 of the 48 frames lie within: if "
            "its units differ from theirs, convert that file (0.0001 m per unit would fit it; --depth-scale applies "
            "to every frame), else remove the frame")


def _units_last_frame_near(folder: Path) -> str:
    _scale_png(folder / "depth" / "frame_00048.png", 0.1)  # centimetres among millimetres
    return "frame_00048.png: frame frame_00048's depth lies 0.0", "(0.01 m per unit would fit it"


def _empty_depth(folder: Path) -> str:
    (folder / "depth" / "000047.png").unlink()
    np.save(folder / "depth" / "000047.npy", np.zeros((0, 0)))
    return "000047.npy: frame 000047's depth image is 0 x 0 pixels (empty); export the frame again, or remove it"


def _flat_depth(folder: Path) -> str:
    (folder / "depth" / "000030.png").unlink()
    np.save(folder / "depth" / "000030.npy", np.full(256, 0.5))
    return "000030.npy: frame 000030's depth image has shape (256,): a depth image is one channel of rows x columns"


def _no_depth(folder: Path) -> str:
    _scale_png(folder / "depth" / "000010.png", 0)
    return "000010.png: frame 000010 holds no depth (every pixel is 0 or NaN)"


def _low_confidence(folder: Path) -> str:
    from PIL import Image

    confidence = sorted((folder / "keyframes" / "confidence").glob("*.png"))[7]
    Image.fromarray(np.zeros((192, 256), dtype=np.uint8)).save(confidence)
    return f"{confidence.name}: frame {confidence.stem} holds no depth at confidence 1 or more: lower --min-confidence"


def _one_frame(folder: Path) -> str:
    for camera in sorted((folder / "keyframes" / "cameras").glob("*.json"))[1:]:
        camera.unlink()
    return ("the capture holds 1 frame, and a surface is kept only where more than 1 frame saw it: fusion needs at "
            "least 2 frames that overlap")


def _nan_translation(folder: Path) -> str:
    pose = folder / "poses" / "000005.txt"
    matrix = np.loadtxt(pose)
    matrix[2, 3] = np.nan
    np.savetxt(pose, matrix)
    return "000005.txt: frame 000005: line 3, number 4 is nan (its translation's z): a pose must be finite numbers"


def _nan_transform_matrix(folder: Path) -> str:
    transforms = json.loads((folder / "transforms.json").read_text())
    transforms["frames"][4]["transform_matrix"][0][3] = float("nan")
    (folder / "transforms.json").write_text(json.dumps(transforms))  # json writes NaN, as numpy-made exports do
    return "transforms.json: frame 4 (frame_00005): transform_matrix[0][3] is nan (its translation's x)"


def _inf_polycam_rotation(folder: Path) -> str:
    camera = sorted((folder / "keyframes" / "cameras").glob("*.json"))[2]
    data = json.loads(camera.read_text())
    data["t_11"] = float("inf")
    camera.write_text(json.dumps(data))
    return f"{camera.name}: frame {camera.stem}: t_11 is inf (its rotation)"


def _name_with_space(folder: Path) -> str:
    camera = sorted((folder / "keyframes" / "cameras").glob("*.json"))[3]
    camera.rename(camera.with_name(f"{camera.stem} copy.json"))
    return f"the frame name '{camera.stem} copy' holds a space: a frame name is letters, digits"


def _name_with_backslash(folder: Path) -> str:
    transforms = json.loads((folder / "transforms.json").read_text())
    transforms["frames"][6]["file_path"] = "images\\frame_00007.png"  # a Windows path
    (folder / "transforms.json").write_text(json.dumps(transforms))
    return "frame 6: file_path 'images\\\\frame_00007.png': the frame name 'images\\\\frame_00007' holds a backslash"


BAD = {"empty-folder": ("depth", _empty, []), "unknown-format": ("depth", _unknown, []),
       "missing-depth": ("polycam", _missing_depth, []), "missing-image": ("nerfstudio", _missing_image, []),
       "not-rigid": ("depth", _not_rigid, []), "wrong-size": ("depth", _wrong_size, []),
       "wrong-units": ("polycam", lambda folder: "all 48 frames do: are the units wrong? try --depth-scale 0.001",
                       ["--depth-scale", "1"]),
       "units-10x-every-frame": ("depth", lambda folder: "are the units wrong? try --depth-scale 0.001; if it is that "
                                 "far, raise --max-depth", ["--depth-scale", "0.01"]),
       "units-one-frame": ("depth", _units_middle_frame, []),
       "units-one-frame-near": ("nerfstudio", _units_last_frame_near, []),
       "empty-depth-image": ("depth", _empty_depth, []), "flat-depth-array": ("depth", _flat_depth, []),
       "no-depth": ("depth", _no_depth, []), "low-confidence": ("polycam", _low_confidence, []),
       "one-frame": ("polycam", _one_frame, []),
       "nan-translation": ("depth", _nan_translation, []),
       "nan-transform-matrix": ("nerfstudio", _nan_transform_matrix, []),
       "inf-polycam-rotation": ("polycam", _inf_polycam_rotation, []),
       "frame-name-space": ("polycam", _name_with_space, []),
       "frame-name-backslash": ("nerfstudio", _name_with_backslash, [])}


@pytest.mark.parametrize("case", BAD)
def test_bad_capture_is_one_line_and_writes_nothing(case, captures, tmp_path, capsys):
    fmt, damage, options = BAD[case]
    folder = copy(captures, fmt, tmp_path)
    expected = damage(folder)
    output = tmp_path / "cloud.ply"
    code = cli.main(["capture", "fuse", str(folder), "--output", str(output), *options])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1, err
    assert err.startswith("data_tools capture fuse: error: ") and "Traceback" not in err
    for part in (expected,) if isinstance(expected, str) else expected:
        assert part in err, err
    assert not output.exists() and not list(tmp_path.glob("cloud*"))


@pytest.fixture(scope="module")
def plant_capture(captures):
    return read_capture(captures["depth"])


@pytest.mark.parametrize("scale", ["plant", "row"])
def test_every_frame_is_read_and_checked_with_depth_in_range(plant_capture, scale):
    config = fusion_config(scale)
    depths = frame_depths(plant_capture, config)
    assert len(depths) == FRAMES
    for depth, _ in depths:  # what Open3D integrates: every frame holds depth within max_depth
        assert depth.dtype == np.float32 and ((depth > 0) & (depth <= config.max_depth)).any()


def test_depth_bounds_come_from_the_scale():
    assert depth_bounds(fusion_config("plant")) == pytest.approx((0.1, 1.5))
    assert depth_bounds(fusion_config("row")) == pytest.approx((0.2, 3.0))
    assert depth_bounds(fusion_config("plant", max_depth=2.0)) == pytest.approx((0.1, 2.0))
    with pytest.raises(ConfigError, match=r"max_depth \(0.08 m\) must be beyond 20 voxels \(0.1 m\)"):
        fusion_config("plant", max_depth=0.08)


@pytest.mark.parametrize("scale", ["plant", "row"])
@pytest.mark.parametrize("factor", [10.0, 0.1, 1000.0])
@pytest.mark.parametrize("index", [0, FRAMES // 2, FRAMES - 1])
def test_a_units_error_on_any_frame_is_refused_before_any_fusion(plant_capture, scale, factor, index, monkeypatch):
    import open3d as o3d

    def no_fusion(*args, **kwargs):
        raise AssertionError("the fusion started before every frame was checked")

    monkeypatch.setattr(o3d.t.geometry, "VoxelBlockGrid", no_fusion)
    frames = list(plant_capture.frames)
    frames[index] = dataclasses.replace(frames[index], depth_scale=0.001 * factor)  # read in other units
    capture = dataclasses.replace(plant_capture, frames=tuple(frames))
    name = frames[index].name
    with pytest.raises(InputFileError) as error:
        fuse(capture, fusion_config(scale), progress=False)
    line = str(error.value)
    assert f"{name}.png: frame {name}'s depth lies " in line and "\n" not in line
    assert f"while {FRAMES - 1} of the {FRAMES} frames lie within" in line
    assert "0.001 m per unit would fit it; --depth-scale applies to every frame" in line


@pytest.mark.parametrize("min_weight, needed", [(1.0, 2), (0.5, 1), (2.0, 3)])
def test_the_frames_a_fusion_needs_follow_min_weight(plant_capture, min_weight, needed):
    config = fusion_config("plant", min_weight=min_weight)
    assert frames_needed(config) == needed
    # so many frames fuse into a surface; one fewer is refused with the reason, not a depth range
    points, _ = fuse(dataclasses.replace(plant_capture, frames=plant_capture.frames[:needed]), config, progress=False)
    assert len(points) > 100
    if needed > 1:
        fewer = dataclasses.replace(plant_capture, frames=plant_capture.frames[:needed - 1])
        with pytest.raises(InputFileError, match=f"holds {needed - 1} frames?, and a surface is kept only where more "
                                                 f"than {min_weight:g} frames? saw it: fusion needs at least {needed}"):
            fuse(fewer, config, progress=False)


def test_views_that_do_not_overlap_are_told_so(plant_capture):
    far = plant_capture.frames[1].camera_to_world.copy()
    far[:3, 3] += [100.0, 0, 0]  # the second frame 100 m away: no voxel seen twice
    frames = (plant_capture.frames[0], dataclasses.replace(plant_capture.frames[1], camera_to_world=far))
    with pytest.raises(PointCloudError, match="no voxel was seen by more than 1 of the 2 frames, so their views do not "
                                        "overlap: are the poses right"):
        fuse(dataclasses.replace(plant_capture, frames=frames), fusion_config("plant"), progress=False)


@pytest.mark.parametrize("shape, expected", [((0, 0), "is 0 x 0 pixels (empty)"), ((0, 256), "is 256 x 0 pixels"),
                                             ((192, 0), "is 0 x 192 pixels"), ((192,), "has shape (192,)"),
                                             ((192, 256, 3), "has shape (192, 256, 3)")])
def test_an_empty_or_flat_depth_image_is_refused_naming_its_frame(plant_capture, shape, expected):
    frame = plant_capture.frames[3]
    with pytest.raises(InputFileError, match=re.escape(f"frame {frame.name}'s depth image {expected}")):
        depth_intrinsics(frame, shape)


@pytest.mark.parametrize("name", ["000000", "1000000", "frame_00001", "1700000000.123", "a-b_c.d", "IMG9"])
def test_frame_names_that_follow_the_rule(name):
    assert check_frame_name(name, "file") == name


def test_the_names_tpvp_writes_follow_the_rule():
    for image in frame_names(3, [".png", ".JPG", ".jpeg"]):  # the images tpvp exports for nerfstudio and COLMAP
        assert check_frame_name(Path(image).stem, image) == Path(image).stem


@pytest.mark.parametrize("name, fault", [("frame 1", "holds a space"), ("a/b", "holds a slash"),
                                         ("a\\b", "holds a backslash"), ("", "is empty"),
                                         (".hidden", "starts with '.'"), ("-x", "starts with '-'"),
                                         ("\u00e91", "starts with '\u00e9'"), ("x:y", "holds ':'")])
def test_frame_names_against_the_rule_are_refused(name, fault):
    with pytest.raises(InputFileError) as error:
        check_frame_name(name, "cameras/x.json")
    assert str(error.value) == (f"cameras/x.json: the frame name {name!r} {fault}: a frame name is letters, digits, "
                                f"'.', '-' and '_', starting with a letter or digit (no spaces or slashes); rename "
                                f"the frame's files")
