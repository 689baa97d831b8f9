"""`tpvp export`: a plan's views as MoveIt pose goals and as a ROS 2 bag in the robot's frame, a
session's captures (or a plan's views) as nerfstudio's transforms.json and a COLMAP model; each read
back with the receiving side's own reader (PyYAML, rosbags, json and open3d, pycolmap) and checked
against the plan or the session's poses to 1e-9. Bad input is one line, exit status 2, nothing written."""

import json

import numpy as np
import open3d as o3d
import pandas as pd
import pycolmap
import pytest
import yaml
from rosbags.interfaces import QosDurability
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore

from helpers import benchmark_module, tree_digest
from tpvp.cli import main
from tpvp.export.poses import quaternion_to_rotation
from tpvp.io.plan import plan_table, read_plan, write_plan
from tpvp.sensor.camera import D435, look_at_rotations, project, rotation_to_quaternion, switch_camera_axes
from tpvp.session import Session


@pytest.fixture
def plan_folder(tmp_path):
    rng = np.random.default_rng(7)
    positions = rng.normal(size=(6, 3))
    look_ats = 0.1 * rng.normal(size=(6, 3))
    quaternions = [rotation_to_quaternion(r) for r in look_at_rotations(positions, look_ats)]
    roles = ["initial", "warm-up NBV"] + ["planned"] * 4
    write_plan(tmp_path, {"scan": plan_table(positions, look_ats, quaternions, roles)}, {"scan": "the scans' frame"})
    return tmp_path


def _rigid(rng) -> np.ndarray:
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    matrix = np.eye(4)
    matrix[:3, :3] = q * np.sign(np.linalg.det(q))
    matrix[:3, 3] = rng.normal(size=3)
    return matrix


def test_moveit_goals_are_the_plan_in_the_base_frame(plan_folder, tmp_path, capsys):
    matrix = _rigid(np.random.default_rng(3))
    (tmp_path / "base.yaml").write_text(yaml.safe_dump({"matrix": matrix.tolist()}))
    out = tmp_path / "goals.yaml"
    assert main(["export", "moveit", str(plan_folder), "--base-from-scan", str(tmp_path / "base.yaml"),
                 "--frame", "panda_link0", "--output", str(out)]) == 0
    assert "6 pose goals in frame 'panda_link0'" in capsys.readouterr().out
    goals = yaml.safe_load(out.read_text())
    plan = pd.read_csv(plan_folder / "plan.csv", comment="#")
    assert goals["frame_id"] == "panda_link0" and [g["step"] for g in goals["pose_goals"]] == plan["step"].tolist()
    for goal, row in zip(goals["pose_goals"], plan.itertuples()):
        position = [goal["position"][a] for a in "xyz"]
        assert np.allclose(position, matrix[:3, :3] @ [row.x, row.y, row.z] + matrix[:3, 3], atol=1e-9)
        orientation = quaternion_to_rotation([goal["orientation"][a] for a in "xyzw"])
        assert np.allclose(orientation, matrix[:3, :3] @ quaternion_to_rotation([row.qx, row.qy, row.qz, row.qw]),
                           atol=1e-9)
        assert goal["role"] == row.role


def test_without_a_transform_the_goals_are_the_plan(plan_folder, tmp_path):
    out = tmp_path / "goals.yaml"
    assert main(["export", "moveit", str(plan_folder / "plan.csv"), "--output", str(out)]) == 0
    plan = pd.read_csv(plan_folder / "plan.csv", comment="#")
    for goal, row in zip(yaml.safe_load(out.read_text())["pose_goals"], plan.itertuples()):
        assert [goal["position"][a] for a in "xyz"] == pytest.approx([row.x, row.y, row.z], abs=1e-12)
        q = np.array([goal["orientation"][a] for a in "xyzw"])
        assert min(np.abs(q - [row.qx, row.qy, row.qz, row.qw]).max(),
                   np.abs(q + [row.qx, row.qy, row.qz, row.qw]).max()) < 1e-12  # q and -q: one rotation


@pytest.mark.parametrize("fmt,output", [("moveit", "goals.yaml"), ("ros2", "bag")])
@pytest.mark.parametrize("matrix,expected", [
    (np.diag([2.0, 2.0, 2.0, 1.0]).tolist(), "not a rigid transform"),
    ([[1, 0, 0], [0, 1, 0]], "4x4 matrix"),
    ("no matrix here", "4x4 matrix"),
])
def test_a_transform_that_is_not_rigid_is_one_line_and_nothing_is_written(plan_folder, tmp_path, capsys, matrix,
                                                                          expected, fmt, output):
    (tmp_path / "base.json").write_text(yaml.safe_dump(matrix))
    out = tmp_path / output
    assert main(["export", fmt, str(plan_folder), "--base-from-scan", str(tmp_path / "base.json"),
                 "--output", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and expected in err[0] and "base.json" in err[0] and not out.exists()


def test_a_missing_plan_is_one_line(tmp_path, capsys):
    assert main(["export", "moveit", str(tmp_path / "nowhere"), "--output", str(tmp_path / "g.yaml")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no such plan" in err[0]


# --- ROS 2 bag ------------------------------------------------------------------------------------

def _bag(folder) -> dict:
    """Topic -> (log time, message, offered QoS) of a bag, read with rosbags' reader and typestore."""
    typestore = get_typestore(Stores.ROS2_HUMBLE)
    with Reader(folder) as reader:
        assert reader.metadata["storage_identifier"] == "mcap" and reader.metadata["version"] == 8
        return {connection.topic: (stamp, typestore.deserialize_cdr(data, connection.msgtype),
                                   connection.ext.offered_qos_profiles)
                for connection, stamp, data in reader.messages()}


def _matrix(position, quaternion) -> np.ndarray:
    """A 4x4 camera-to-frame matrix from a position and a quaternion (x, y, z, w)."""
    matrix = np.eye(4)
    matrix[:3, :3] = quaternion_to_rotation(quaternion)
    matrix[:3, 3] = position
    return matrix


def _pose_matrix(pose) -> np.ndarray:
    """A geometry_msgs/Pose as a 4x4 matrix."""
    p, q = pose.position, pose.orientation
    return _matrix([p.x, p.y, p.z], [q.x, q.y, q.z, q.w])


def _plan_matrices(plan_folder) -> list:
    plan = pd.read_csv(plan_folder / "plan.csv", comment="#")
    return [_matrix([r.x, r.y, r.z], [r.qx, r.qy, r.qz, r.qw]) for r in plan.itertuples()]


def test_the_ros2_bag_holds_the_plan_in_the_robots_frame(plan_folder, tmp_path, capsys):
    matrix = _rigid(np.random.default_rng(5))
    (tmp_path / "base.json").write_text(json.dumps(matrix.tolist()))
    out = tmp_path / "plan_bag"
    assert main(["export", "ros2", str(plan_folder), "--base-from-scan", str(tmp_path / "base.json"),
                 "--frame", "panda_link0", "--stamp", "1700000000.25", "--output", str(out)]) == 0
    assert "6 views on /tpvp/views and /tpvp/route in frame 'panda_link0'" in capsys.readouterr().out
    assert (out / "metadata.yaml").is_file() and (out / "plan_bag.mcap").is_file()
    bag = _bag(out)
    assert sorted(bag) == ["/tf_static", "/tpvp/route", "/tpvp/views"]
    expected = [matrix @ pose for pose in _plan_matrices(plan_folder)]
    views, route = bag["/tpvp/views"][1], bag["/tpvp/route"][1]
    assert (views.header.frame_id, views.header.stamp.sec, views.header.stamp.nanosec) == ("panda_link0", 1700000000,
                                                                                        250_000_000)
    assert len(views.poses) == len(route.poses) == len(expected)
    for pose, stamped, want in zip(views.poses, route.poses, expected):  # in plan order
        assert np.allclose(_pose_matrix(pose), want, atol=1e-9)
        assert np.allclose(_pose_matrix(stamped.pose), want, atol=1e-9)
        assert stamped.header.frame_id == "panda_link0" and stamped.header.stamp.sec == 1700000000
    (transform,) = bag["/tf_static"][1].transforms
    assert (transform.header.frame_id, transform.child_frame_id) == ("panda_link0", "tpvp_scan")
    t, q = transform.transform.translation, transform.transform.rotation
    assert np.allclose(_matrix([t.x, t.y, t.z], [q.x, q.y, q.z, q.w]), matrix, atol=1e-9)
    for stamp, _, qos in bag.values():  # logged at the stamp; latched for late subscribers
        assert stamp == 1_700_000_000_250_000_000 and qos[0].durability == QosDurability.TRANSIENT_LOCAL


def test_without_options_the_bag_is_the_plan_stamped_zero_and_the_same_on_every_run(plan_folder, tmp_path):
    out = tmp_path / "bag"
    assert main(["export", "ros2", str(plan_folder / "plan.csv"), "--output", str(out)]) == 0
    first = (out / "bag.mcap").read_bytes()
    assert main(["export", "ros2", str(plan_folder / "plan.csv"), "--output", str(out), "--force"]) == 0
    assert (out / "bag.mcap").read_bytes() == first
    bag = _bag(out)
    views = bag["/tpvp/views"][1]
    assert views.header.frame_id == "map" and (views.header.stamp.sec, views.header.stamp.nanosec) == (0, 0)
    for pose, expected in zip(views.poses, _plan_matrices(plan_folder)):
        assert np.allclose(_pose_matrix(pose), expected, atol=1e-12)
    (transform,) = bag["/tf_static"][1].transforms
    assert [transform.transform.rotation.w, transform.transform.translation.x] == [1.0, 0.0]
    assert {stamp for stamp, _, _ in bag.values()} == {10**9}  # a zero stamp is logged at 1 s


@pytest.mark.parametrize("argv,expected", [
    (["--output", "{tmp}/plan.mcap"], "a ROS 2 bag is a folder"),
    (["--output", "{tmp}/bag", "--stamp", "-1"], "a ROS time is 0 to 2147483647 seconds"),
    (["--output", "{tmp}/bag", "--stamp", "nan"], "a ROS time is 0 to"),
    (["--output", "{tmp}/bag", "--stamp", "noon"], "--stamp noon: a ROS time"),
    (["--output", "{tmp}/bag", "--frame", "tpvp_scan"], "--frame 'tpvp_scan': the robot's frame is a tf2 frame"),
    (["--output", "{tmp}/bag", "--frame", "/map"], "no leading '/'"),
])
def test_a_bad_bag_option_is_one_line_and_nothing_is_written(plan_folder, tmp_path, capsys, argv, expected):
    argv = [a.format(tmp=tmp_path) for a in argv]
    assert main(["export", "ros2", str(plan_folder), *argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and expected in err[0]
    assert not (tmp_path / "plan.mcap").exists() and not (tmp_path / "bag").exists()


# --- a session's captures: nerfstudio and COLMAP ---------------------------------------------------

@pytest.fixture(scope="module")
def session_folder(tmp_path_factory):
    """A session with its warm-up captured (views 17 and 3) by the stand-in camera; read only."""
    return benchmark_module("session_faults").prepare(tmp_path_factory.mktemp("session"))["ready"]


def _requests(folder):
    session = Session.open(folder)
    return [session.pose_request(c["view"], "") for c in session.captures], session.fused_model()


def test_the_colmap_model_read_by_pycolmap_holds_the_session_poses(session_folder, tmp_path, capsys):
    out = tmp_path / "colmap"
    assert main(["export", "colmap", str(session_folder), "--output", str(out)]) == 0
    assert "2 captures" in capsys.readouterr().out
    requests, fused = _requests(session_folder)
    model = pycolmap.Reconstruction(str(out))
    (camera,) = model.cameras.values()
    assert camera.model.name == "PINHOLE" and (camera.width, camera.height) == (D435.width, D435.height)
    assert np.allclose(camera.params, [D435.fx, D435.fy, D435.cx + 0.5, D435.cy + 0.5], atol=1e-12)
    images = [model.images[i] for i in sorted(model.images)]
    assert [image.name for image in images] == ["frame_00001.png", "frame_00002.png"]
    for image, request in zip(images, requests):
        rotation = quaternion_to_rotation(request.quaternion)  # camera-to-world, OpenCV axes
        assert np.allclose(image.projection_center(), request.position, atol=1e-9)
        assert np.allclose(image.cam_from_world().rotation.matrix(), rotation.T, atol=1e-9)  # world-to-camera
        # COLMAP's pixel centres are half a pixel off tpvp's (OpenCV's): the same point, the same pixel.
        u, v, _ = project(fused[:5], request.position, rotation, D435)
        assert np.allclose([image.project_point(p) for p in fused[:5]], np.c_[u, v] + 0.5, atol=1e-6)
    points = np.array([model.points3D[i].xyz for i in sorted(model.points3D)])
    assert np.allclose(points, fused, atol=1e-9)
    assert all(model.points3D[i].track.length() == 0 for i in model.points3D)


def test_colmap_from_a_plan_gives_its_views_as_known_poses(plan_folder, tmp_path):
    out = tmp_path / "colmap"
    assert main(["export", "colmap", str(plan_folder), "--output", str(out)]) == 0
    model = pycolmap.Reconstruction(str(out))
    plan = pd.read_csv(plan_folder / "plan.csv", comment="#")
    centres = [model.images[i].projection_center() for i in sorted(model.images)]
    assert np.allclose(centres, plan[["x", "y", "z"]].to_numpy(), atol=1e-9) and len(model.points3D) == 0


def _looks_at(transform_matrix, position, look_at) -> bool:
    """Whether an OpenGL camera-to-world pose looks along its -z axis from ``position`` to ``look_at``."""
    forward = np.asarray(look_at) - position
    return bool(np.allclose(-np.asarray(transform_matrix)[:3, 2], forward / np.linalg.norm(forward), atol=1e-9))


def test_nerfstudio_transforms_hold_the_session_poses_in_opengl_axes(session_folder, tmp_path, capsys):
    out = tmp_path / "ns"
    assert main(["export", "nerfstudio", str(session_folder), "--output", str(out)]) == 0
    said = capsys.readouterr().out
    assert f"place the 2 colour images there as {out / 'images' / 'frame_00001.png'} ... frame_00002.png" in said
    transforms = json.loads((out / "transforms.json").read_text())
    requests, fused = _requests(session_folder)
    assert transforms["camera_model"] == "OPENCV" and transforms["ply_file_path"] == "sparse_pc.ply"
    assert [transforms[k] for k in ("fl_x", "fl_y", "cx", "cy", "w", "h", "k1", "k2", "p1", "p2")] == \
        [D435.fx, D435.fy, D435.cx + 0.5, D435.cy + 0.5, D435.width, D435.height, 0, 0, 0, 0]
    frames = transforms["frames"]
    assert [f["file_path"] for f in frames] == ["images/frame_00001.png", "images/frame_00002.png"]
    for frame, request in zip(frames, requests):
        matrix = np.array(frame["transform_matrix"])
        assert np.allclose(matrix[:3, 3], request.position, atol=1e-9)
        assert np.allclose(matrix[:3, :3] @ np.diag([1.0, -1.0, -1.0]), quaternion_to_rotation(request.quaternion),
                           atol=1e-9)
        assert _looks_at(matrix, request.position, request.look_at)
        assert not _looks_at(switch_camera_axes(matrix), request.position, request.look_at)  # OpenCV axes would fail
        assert matrix[2, 1] > 0  # OpenGL's y is the image's up: the views look at the plant from beside it
    cloud = o3d.io.read_point_cloud(str(out / "sparse_pc.ply"))  # as nerfstudio reads its initial points
    assert np.allclose(np.asarray(cloud.points), fused, atol=1e-9)
    assert np.allclose(np.asarray(cloud.colors), 128 / 255) and len(cloud.colors) == len(fused)


def test_the_images_are_copied_in_capture_order_with_the_given_intrinsics(session_folder, tmp_path, capsys):
    images = tmp_path / "kept"
    images.mkdir()
    (images / "b_second.jpg").write_bytes(b"second")
    (images / "a_first.png").write_bytes(b"first")
    (images / "notes.txt").write_text("not an image")
    (tmp_path / "k.yaml").write_text("{fx: 600, fy: 601, cx: 319.5, cy: 239.5, width: 640, height: 480}")
    out = tmp_path / "ns"
    assert main(["export", "nerfstudio", str(session_folder), "--images", str(images), "--intrinsics",
                 str(tmp_path / "k.yaml"), "--output", str(out)]) == 0
    assert "place the" not in capsys.readouterr().out
    transforms = json.loads((out / "transforms.json").read_text())
    assert [f["file_path"] for f in transforms["frames"]] == ["images/frame_00001.png", "images/frame_00002.jpg"]
    assert (out / "images" / "frame_00001.png").read_bytes() == b"first"
    assert (out / "images" / "frame_00002.jpg").read_bytes() == b"second"
    assert [transforms[k] for k in ("fl_x", "fl_y", "cx", "cy", "w", "h")] == [600, 601, 320, 240, 640, 480]


def _one_line_and_nothing_written(argv, capsys, output, expected):
    before = tree_digest(output) if output.is_dir() else None
    assert main([str(a) for a in argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and expected in err[0], err
    assert (tree_digest(output) == before) if before is not None else not output.exists()


@pytest.mark.parametrize("fmt", ["nerfstudio", "colmap"])
def test_an_image_count_other_than_the_captures_is_one_line(session_folder, tmp_path, capsys, fmt):
    images = tmp_path / "kept"
    images.mkdir()
    for name in ("1.png", "2.png", "3.png"):
        (images / name).write_bytes(b"png")
    _one_line_and_nothing_written(["export", fmt, session_folder, "--images", images, "--output", tmp_path / "out"],
                                  capsys, tmp_path / "out", "3 images (.png/.jpg/.jpeg) for 2 captures")


@pytest.mark.parametrize("fmt", ["nerfstudio", "colmap"])
@pytest.mark.parametrize("source,expected", [("nowhere", "no such session folder"),
                                             ("empty", "not a session folder (no session.json)")])
def test_a_missing_folder_or_one_that_is_not_a_session_is_one_line(tmp_path, capsys, fmt, source, expected):
    (tmp_path / "empty").mkdir()
    _one_line_and_nothing_written(["export", fmt, tmp_path / source, "--output", tmp_path / "out"], capsys,
                                  tmp_path / "out", expected)


@pytest.mark.parametrize("fmt", ["ros2", "nerfstudio", "colmap"])
def test_an_existing_output_is_kept_unless_forced(plan_folder, session_folder, tmp_path, capsys, fmt):
    source = plan_folder if fmt == "ros2" else session_folder
    out = tmp_path / "out"
    assert main(["export", fmt, str(source), "--output", str(out)]) == 0
    _one_line_and_nothing_written(["export", fmt, source, "--output", out], capsys, out,
                                  f"{out} exists: choose a new one, or --force to replace it")
    (out / "mine.txt").write_text("a file no export wrote")
    _one_line_and_nothing_written(["export", fmt, source, "--output", out, "--force"], capsys, out,
                                  "holds files that no tpvp run recorded as its own (mine.txt)")
    (out / "mine.txt").unlink()
    assert main(["export", fmt, str(source), "--output", str(out), "--force"]) == 0


# --- a plan.csv that is not a plan (issue 47) ------------------------------------------------------

def _plan_edit(line, column, value):
    """plan.csv with one value replaced (line counting from 1, column from 0)."""
    def edit(text):
        lines = text.splitlines()
        values = lines[line - 1].split(",")
        values[column] = value
        lines[line - 1] = ",".join(values)
        return "\n".join(lines) + "\n"
    return edit


# damage of the plan_folder fixture's plan.csv (a comment line, the header, 6 views) -> the line's key text
PLAN_FAULTS = {
    "not a number": (_plan_edit(5, 8, "abc"), "plan.csv: line 5, column 'qx': 'abc' is not a number; correct it"),
    "NaN": (_plan_edit(4, 2, "nan"), "plan.csv: line 4, column 'x': nan is not a finite number"),
    "infinite": (_plan_edit(6, 7, "-inf"), "plan.csv: line 6, column 'look_z': -inf is not a finite number"),
    "no value": (_plan_edit(3, 11, ""), "plan.csv: line 3, column 'qw': no value"),
    "step not whole": (_plan_edit(3, 0, "0.5"), "plan.csv: line 3, column 'step': 0.5 is not a whole number"),
    "zero quaternion": (lambda t: _plan_edit(3, 8, "0")(_plan_edit(3, 9, "0")(_plan_edit(3, 10, "0")(
        _plan_edit(3, 11, "0")(t)))), "plan.csv: line 3, columns qx, qy, qz, qw: the quaternion's norm is 0, not 1"),
    "missing column": (lambda t: t.replace(",qz,qw", ",qz"), "plan.csv: not a tpvp plan: its header (line 2) has no "
                                                             "column qw; give a plan.csv written by tpvp plan"),
    "truncated": (lambda t: t[: len(t) - 40], "plan.csv: line 8 has "),
    "no views": (lambda t: "\n".join(t.splitlines()[:2]) + "\n",
                 "plan.csv: the plan has no views (nothing after its header, line 2)"),
    "empty": (lambda t: "", "plan.csv: empty: no header line"),
}


@pytest.mark.parametrize("fmt", ["moveit", "ros2", "colmap"])
@pytest.mark.parametrize("fault", PLAN_FAULTS)
def test_a_plan_that_is_not_one_is_one_line_naming_line_and_column(plan_folder, tmp_path, capsys, fmt, fault):
    damage, expected = PLAN_FAULTS[fault]
    plan = plan_folder / "plan.csv"
    plan.write_text(damage(plan.read_text()))
    output = tmp_path / ("goals.yaml" if fmt == "moveit" else "out")
    _one_line_and_nothing_written(["export", fmt, plan, "--output", output], capsys, output, expected)


def test_a_plan_edited_by_hand_reads_as_pandas_reads_it(plan_folder):
    """Comments after values, blank lines and quaternions rounded to 3 decimals are a plan still."""
    lines = (plan_folder / "plan.csv").read_text().splitlines()
    values = lines[2].split(",")
    values[8:] = [f"{float(v):.3f}" for v in values[8:]]
    lines[2] = ",".join(values) + "  # rounded by hand"
    (plan_folder / "plan.csv").write_text("\n".join(lines[:3] + [""] + lines[3:]) + "\n")
    table = read_plan(plan_folder)
    expected = pd.read_csv(plan_folder / "plan.csv", comment="#")
    assert list(table.columns) == list(expected.columns) and table["step"].tolist() == list(range(6))
    assert table["role"].tolist() == expected["role"].tolist()
    np.testing.assert_array_equal(table[expected.columns[2:]].to_numpy(), expected[expected.columns[2:]].to_numpy())
