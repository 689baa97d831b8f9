"""Real sessions (tpvp.session, `tpvp session ...`): the plan of a session fed with the captures a
camera takes at the poses it asks for equals the simulator's plan of the same pair (planning frame
from the previous model, native scale), for clouds and depth images; the exported model equals the
simulator's fused model; bad input is one line, exit status 2, the session folder unchanged."""

import json
from pathlib import Path

import numpy as np
import pytest

from helpers import tree_digest
from tpvp.cli import main
from tpvp.config_loading import make_config
from tpvp.simulate.single_plant import run_case
from tpvp.io import faults, write_point_cloud
from tpvp.scene import voxels
from tpvp.scene.samples import load_sample, sample_path
from tpvp.sensor.camera import D435
from tpvp.session import Session
from tpvp.simulate.robot_camera import RowStandInCamera, StandInCamera

CASES = [(space, initial) for space in ("hemisphere", "sphere") for initial in (17, 8, 21)]


@pytest.fixture(scope="module")
def pair():
    return load_sample("tomato_0305"), load_sample("tomato_0306")


def _play(session: Session, camera: StandInCamera, kind: str, planned: bool = False) -> None:
    """Capture every pose the session asks for (the warm-up; with ``planned`` the planned views too)."""
    while True:
        request = session.request()
        if request.view is None:
            if planned and request.role == "plan":
                session.plan()
                continue
            return
        if kind == "depth":
            session.add_depth(camera.depth(request.view), D435, request.view, f"view {request.view}")
        else:
            session.add(camera.cloud(request.view), request.view, f"view {request.view}")


@pytest.mark.parametrize("kind", ["cloud", "depth"])
@pytest.mark.parametrize("space,initial", CASES)
def test_the_session_plans_what_the_simulator_plans(tmp_path, pair, space, initial, kind):
    # Depth images are rendered per pixel, so the simulator observes with the pixel model too.
    config = make_config("plant", {"view_space": space, "initial_view": initial,
                                   **({"sensor.model": "pixel"} if kind == "depth" else {})})
    camera = StandInCamera(*pair, config)
    simulated = run_case(camera.scene, camera.config)
    session = Session.start(tmp_path / "session", pair[0], config, "tomato_0305")
    _play(session, camera, kind)
    planned = session.plan()
    assert planned.executed_views == simulated.executed_views
    assert planned.planned_views == simulated.planned_views
    assert abs(planned.path_length - simulated.path_length) <= 1e-9
    assert Session.open(tmp_path / "session").state["plan"]["planned_views"] == simulated.planned_views


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["cloud", "depth"])
def test_a_row_session_plans_what_the_simulator_plans(tmp_path, kind):
    from tpvp.config_loading import load_config
    from tpvp.simulate.greenhouse import run_row_case
    from tpvp.simulate.row_cases import QUICK, RowCase

    # A depth image of the simulator's voxel cubes gives surface points, not the row's points:
    # its passive reconstruction is the voxel centres (coarse = centres), on both sides.
    # Two rounds of look-at targets (200 candidates, not 800): the pixel sensor's visibility of
    # every candidate is most of this test's time, and the equivalence does not depend on their count.
    config = load_config("paper-row", {**QUICK, "view_space": "room1", "targets.rounds": 2,
                                       **({"sensor.model": "pixel", "coarse": "centres"} if kind == "depth" else {})})
    previous, current = RowCase("room1", 0, 0).load()
    camera = RowStandInCamera(previous, current, config, cache_dir=tmp_path / "oracles")
    simulated = run_row_case(camera.scene, config)
    session = Session.start(tmp_path / "session", previous, config, "generated room1 row, session 0")
    while (request := session.request()).view is not None:
        assert request.role.startswith("passive sweep view")
        if kind == "depth":
            session.add_depth(camera.depth(request.position, request.look_at), D435, request.view, "depth")
        else:
            session.add(camera.cloud(request.position, request.look_at), request.view, "cloud")
    assert len(session.captures) == 15
    planned = session.plan()
    assert np.array_equal(planned.positions, simulated.positions)
    assert np.array_equal(planned.look_ats, simulated.look_ats)
    assert abs(planned.path_length - simulated.path_length) <= 1e-9
    assert session.request().role == f"planned view 1 of {len(simulated.planned_views)}"
    assert Session.problems(tmp_path / "session") == []  # a row's plan record and files read as `check` reads them


def test_the_exported_model_is_the_simulators_fused_model(tmp_path, pair):
    config = make_config("plant")
    camera = StandInCamera(*pair, config)
    session = Session.start(tmp_path / "session", pair[0], config, "tomato_0305")
    _play(session, camera, "cloud", planned=True)
    views = [c["view"] for c in session.captures]
    assert views == session.state["plan"]["executed_views"] + session.state["plan"]["planned_views"]
    path = session.export(tmp_path / "today.ply")
    from tpvp.io import read_point_cloud

    exported = voxels.voxelise(session.scene.to_planning(read_point_cloud(path, units="m")), config.gt_resolution)
    fused = voxels.voxelise(np.concatenate([camera.scene.observe(v) for v in views]), config.gt_resolution)
    assert np.array_equal(exported, fused)


def test_a_depth_session_exports_its_images_fused(tmp_path, pair):
    """Depth captures keep their images; export fuses them (tpvp.fusion, a plant's defaults) at the
    poses the session asked for, keeps what lies near the previous model and above the table, and
    the model lies on today's scan; ``session check`` counts the images as the captures' files."""
    from scipy.spatial import cKDTree

    from tpvp.fusion.tsdf import DepthFrame, fuse_frames, fusion_config
    from tpvp.io import read_point_cloud
    from tpvp.scene.frame import scan_points

    config = make_config("plant")
    camera = StandInCamera(*pair, config)
    session = Session.start(tmp_path / "session", pair[0], config, "tomato_0305")
    _play(session, camera, "depth")
    model = read_point_cloud(session.export(tmp_path / "today.ply"), units="m")
    # by hand: the stand-in's images at the views' poses (world frame), fused, cropped
    frames = [DepthFrame(np.nan_to_num(camera.depth(c["view"]), nan=0.0).astype(np.float32), D435,
                         session.view_pose(c["view"])) for c in session.captures]
    fused = fuse_frames(frames, fusion_config("plant"), progress=False).points
    planning = session.scene.to_planning(fused)
    lo, hi = session.scene.previous.min(axis=0), session.scene.previous.max(axis=0)
    near = np.all((planning >= lo - 0.5 * (hi - lo).max()) & (planning <= hi + 0.5 * (hi - lo).max()), axis=1)
    top = session.scene.table_points[:, 2].max() + 0.5 * session.config.scene.table_resolution
    above = (np.floor(planning[:, 2] / config.gt_resolution) + 1) * config.gt_resolution > top + 1e-9 * config.gt_resolution
    assert np.allclose(model, fused[near & above])
    today = scan_points(camera.scene.plant_from_scan, camera.scene.current)
    assert np.percentile(cKDTree(today).query(model)[0], 95) <= 0.005  # within a fusion voxel of today's scan
    assert Session.problems(session.folder) == []
    (session.folder / "captures" / "000_depth.npz").unlink()
    (problem,) = Session.problems(session.folder)
    assert "000_depth.npz" in problem.line(session.folder) and problem.repair.startswith("drop capture 1")


def test_the_command_line_session(tmp_path, pair, capsys):
    camera = StandInCamera(*pair, make_config("plant"))
    folder = tmp_path / "session"
    assert main(["session", "start", "--previous", str(sample_path("tomato_0305")), "--output", str(folder)]) == 0
    out = capsys.readouterr().out
    assert "next: capture view 17 (initial view) at (" in out and "quaternion xyzw" in out
    for step in range(2):
        view = Session.open(folder).request().view
        capture = tmp_path / f"capture{step}.ply"
        write_point_cloud(capture, 1e3 * camera.cloud(view))  # millimetres, as the previous model's file
        assert main(["session", "add", str(folder), "--cloud", str(capture)]) == 0
        assert f"view {view}," in capsys.readouterr().out
    assert main(["session", "plan", str(folder)]) == 0
    out = capsys.readouterr().out
    assert "6 to capture: 20, 4, 9, 7, 31, 27" in out and "next: capture view 20 (planned view 1 of 6)" in out
    plan = (folder / "plan" / "plan.csv").read_text()
    assert plan.count("planned") == 6 and (folder / "plan" / "recording.rrd").is_file()
    assert main(["session", "export", str(folder), "--model", str(tmp_path / "today.ply")]) == 0
    assert (tmp_path / "today.ply").is_file()


# --- bad input: one line, exit status 2, the folder as it was ---------------------------------------

@pytest.fixture
def started(tmp_path, pair):
    folder = tmp_path / "session"
    Session.start(folder, pair[0], make_config("plant"), "tomato_0305.xyz.gz", units="mm")
    return folder


def _refused(argv, folder, capsys, *expected):
    before = tree_digest(folder)
    assert main([str(a) for a in argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and ": error: " in err[0], err
    for text in expected:
        assert text in err[0], err[0]
    assert tree_digest(folder) == before


def test_a_capture_in_the_wrong_units(started, tmp_path, pair, capsys):
    capture = tmp_path / "metres.ply"
    write_point_cloud(capture, StandInCamera(*pair, make_config("plant")).cloud(17))  # metres; the session reads mm
    _refused(["session", "add", started, "--cloud", capture], started, capsys,
             "metres.ply: wrong units? --units mm shrinks the cloud", "use --units m")


def test_a_capture_in_another_frame(started, tmp_path, pair, capsys):
    capture = tmp_path / "shifted.ply"
    write_point_cloud(capture, 1e3 * (StandInCamera(*pair, make_config("plant")).cloud(17) + [2.0, 0.0, 0.0]))
    _refused(["session", "add", started, "--cloud", capture], started, capsys,
             "shifted.ply: 100 % of the capture's points lie away from the previous model",
             "m from its centre, the model is 0.0462 m across", "must be in the previous model's frame and units")


def test_a_depth_image_of_another_size(started, tmp_path, capsys):
    depth = tmp_path / "depth.npy"
    np.save(depth, np.full((480, 640), 0.4))
    _refused(["session", "add", started, "--depth", depth], started, capsys,
             "depth.npy: the image is 640 x 480 pixels but the intrinsics say 1280 x 720")


def test_a_session_of_another_version(started, capsys):
    state = json.loads((started / "session.json").read_text())
    (started / "session.json").write_text(json.dumps({**state, "version": 99}))
    _refused(["session", "plan", started], started, capsys, "a session of format version 99",
             "this tpvp reads version 1")


def test_plan_before_any_capture(started, capsys):
    _refused(["session", "plan", started], started, capsys, "no capture yet")


def test_not_a_session_folder(tmp_path, capsys):
    (tmp_path / "x").mkdir()
    _refused(["session", "add", tmp_path / "x", "--pose", "3", "--cloud", "a.ply"], tmp_path / "x", capsys,
             "not a session folder")


def test_a_pose_off_the_candidates_is_snapped_with_a_warning(started, tmp_path, pair, capsys):
    session = Session.open(started)
    request = session.request()
    pose = tmp_path / "pose.json"
    pose.write_text(json.dumps({"position": (request.position + [0.0, 0.0, 0.01]).tolist(),
                                "look_at": request.look_at.tolist()}))
    capture = tmp_path / "capture.ply"
    write_point_cloud(capture, 1e3 * StandInCamera(*pair, make_config("plant")).cloud(request.view))
    assert main(["session", "add", str(started), "--cloud", str(capture), "--pose", str(pose)]) == 0
    err = capsys.readouterr().err
    assert f"pose.json: the pose is 0.01 m from candidate view {request.view}, the nearest" in err
    assert Session.open(started).captures[0]["view"] == request.view


def test_a_full_disk_while_adding_leaves_the_session_as_it_was(started, tmp_path, pair, capsys):
    capture = tmp_path / "capture.ply"
    write_point_cloud(capture, 1e3 * StandInCamera(*pair, make_config("plant")).cloud(17))
    before = tree_digest(started)
    with faults.inject("enospc", 1):
        assert main(["session", "add", str(started), "--cloud", str(capture)]) == 4
    assert "nothing was published" in capsys.readouterr().err
    assert tree_digest(started) == before


def test_the_world_frame_is_the_previous_models(started):
    session = Session.open(started)
    request = session.request()
    previous = session.previous_scan
    centre = 0.5 * (previous.min(axis=0) + previous.max(axis=0))
    assert np.isclose(np.linalg.norm(request.position - centre), 0.4, atol=1e-9)  # 0.4 m around the real plant
    assert Path(started / "config.yaml").read_text().count("frame: previous") == 1


def test_a_session_folder_is_not_started_twice(started, tmp_path, pair, capsys):
    previous = tmp_path / "previous.xyz"
    np.savetxt(previous, 1e3 * pair[0][::4])
    _refused(["session", "start", "--previous", previous, "--output", started], started, capsys,
             "already holds a session: continue it")


def test_a_real_session_plans_at_the_true_size(tmp_path, capsys):
    assert main(["session", "start", "--previous", str(sample_path("tomato_0305")), "--scale", "normalised",
                 "--output", str(tmp_path / "s")]) == 2
    assert "a real session plans at the plant's true size" in capsys.readouterr().err
    assert not (tmp_path / "s").exists()


def test_a_plan_csv_row_is_a_pose_file(tmp_path):
    from tpvp.session import read_pose_file

    plan = tmp_path / "plan.csv"
    plan.write_text("# frame: world\nstep,role,x,y,z,look_x,look_y,look_z,qx,qy,qz,qw\n"
                    "0,planned,0.1,0.2,0.3,0,0,0,0,0,0,1\n")
    pose = read_pose_file(plan)
    assert pose.position.tolist() == [0.1, 0.2, 0.3] and pose.look_at.tolist() == [0, 0, 0]


def test_a_row_session_from_the_command_line(tmp_path, capsys):
    from tpvp.simulate.row_cases import RowCase

    previous = tmp_path / "row.ply"
    write_point_cloud(previous, RowCase("room1", 0, 0).load()[0])
    assert main(["session", "start", "--previous", str(previous), "--units", "m", "--view-space", "room1",
                 "--output", str(tmp_path / "s")]) == 0
    out = capsys.readouterr().out
    assert "15 views to capture first or plan from (room1, the room's frame)" in out
    assert "next: capture view 0 (passive sweep view 1 of 15)" in out
