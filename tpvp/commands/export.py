"""``tpvp export``: a plan handed to a robot's software (MoveIt goals, a ROS 2 bag), a session's
captures handed to reconstruction tools (nerfstudio, COLMAP)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tpvp.config_loading import load_config
from tpvp.errors import ConfigError, InputFileError
from tpvp.export.colmap import write_colmap
from tpvp.export.images import IMAGES, image_files
from tpvp.export.moveit import moveit_goals
from tpvp.export.nerfstudio import PLY_NAME, write_nerfstudio
from tpvp.export.poses import plan_poses, read_transform
from tpvp.export.ros2 import SCAN_FRAME, TOPICS, check_frame, stamp_nanoseconds, write_plan_bag
from tpvp.io import atomic_write_text
from tpvp.io.plan import plan_file, read_plan
from tpvp.io.publish import staged_file, staged_folder
from tpvp.sensor.camera import D435
from tpvp.session import Session, read_intrinsics
from tpvp.session.check import STATE


def _transform(args) -> np.ndarray:
    return read_transform(args.base_from_scan) if args.base_from_scan else np.eye(4)


def _moveit(args) -> int:
    with staged_file(args.output, inputs=[plan_file(args.plan), args.base_from_scan], force=args.force) as staged:
        table = read_plan(args.plan)
        atomic_write_text(staged, moveit_goals(table, args.frame, _transform(args), str(args.plan)))
    print(f"wrote {args.output} ({len(table)} pose goals in frame {args.frame!r})")
    return 0


def _new_output(path: Path, force: bool, what: str) -> None:
    """Refuse an existing output unless ``--force`` (which replaces only what a tpvp run wrote)."""
    if path.exists() and not force:
        raise ConfigError(f"{what} {path} exists: choose a new one, or --force to replace it (an earlier export)")


def _ros2(args) -> int:
    if args.output.suffix.lower() == ".mcap":
        raise ConfigError(f"--output {args.output}: a ROS 2 bag is a folder (metadata.yaml and the .mcap file, what "
                          f"`ros2 bag play` takes): give the folder, e.g. --output {args.output.with_suffix('')}")
    table = read_plan(args.plan)
    frame, matrix, stamp = check_frame(args.frame), _transform(args), stamp_nanoseconds(args.stamp)
    _new_output(args.output, args.force, "bag folder")
    # The plan's own file is the input: a bag may go beside it, in the plan's folder.
    inputs = [plan_file(args.plan), args.base_from_scan]
    with staged_folder(args.output, inputs=inputs, what="bag folder") as stage:
        write_plan_bag(stage.folder, stage.destination.name, table, frame, matrix, stamp)
    print(f"wrote {args.output} (a ROS 2 bag: {len(table)} views on {' and '.join(list(TOPICS)[:2])} in frame "
          f"{frame!r}, /tf_static {frame} -> {SCAN_FRAME})")
    return 0


def _camera_poses(source: Path, intrinsics_file: Path | None, plans: bool = False):
    """``(camera-to-world poses, points, intrinsics, what they are, the file or folder read)`` of a
    session's captures (or, with ``plans``, of a plan's views: no points)."""
    intrinsics = read_intrinsics(intrinsics_file)[0] if intrinsics_file else None
    if plans and not (source / STATE).is_file() and plan_file(source).is_file():
        config = plan_file(source).parent / "config.yaml"  # the configuration the plan was made with
        intrinsics = intrinsics or (load_config(config).sensor.intrinsics if config.is_file() else D435)
        return plan_poses(read_plan(source)), np.zeros((0, 3)), intrinsics, "views", plan_file(source)
    if not source.exists():
        raise InputFileError(f"{source}: no such session folder{' or plan' if plans else ''}")
    session = Session.open(source)
    points = session.fused_model()  # refuses a session without captures
    return session.capture_poses(), points, intrinsics or session.config.sensor.intrinsics, "captures", source


def _reconstruction(args, write, files: str, plans: bool = False) -> int:
    poses, points, intrinsics, what, source = _camera_poses(args.source, args.intrinsics, plans)
    images = image_files(args.images, len(poses), what) if args.images else None
    _new_output(args.output, args.force, "output folder")
    with staged_folder(args.output, inputs=[source, args.images, args.intrinsics]) as stage:
        names = write(stage.folder, poses, intrinsics, points, images)
    print(f"wrote {args.output} ({files}: {len(poses)} {what}, {len(points):,} points; {intrinsics.width} x "
          f"{intrinsics.height} pixels)")
    if images is None:
        print(f"place the {len(names)} colour images there as {args.output / IMAGES / names[0]} ... {names[-1]}, "
              f"in {'capture' if what == 'captures' else 'execution'} order (or export again with --images FOLDER)")
    return 0


def _nerfstudio(args) -> int:
    return _reconstruction(args, write_nerfstudio, f"transforms.json, {PLY_NAME}")


def _colmap(args) -> int:
    return _reconstruction(args, write_colmap, "cameras.txt, images.txt, points3D.txt", plans=True)


def _plan_options(p, output_metavar: str, output_help: str) -> None:
    p.add_argument("plan", type=Path, help="a plan.csv (or the folder holding it) of tpvp plan or tpvp session")
    p.add_argument("--base-from-scan", type=Path, default=None, metavar="FILE",
                   help="JSON or YAML 4x4 rigid transform taking the plan's (scan) frame into the robot's frame, "
                        "metres (default: the identity)")
    p.add_argument("--output", type=Path, required=True, metavar=output_metavar, help=output_help)


def _reconstruction_options(p, metavar: str, source_help: str, output_help: str) -> None:
    p.add_argument("source", type=Path, metavar=metavar, help=source_help)
    p.add_argument("--output", type=Path, required=True, metavar="DIR", help=output_help)
    p.add_argument("--images", type=Path, default=None, metavar="FOLDER",
                   help="the colour images the robot kept, one per capture (.png, .jpg, .jpeg), sorted by name in "
                        "capture order: copied into the output's images/ as frame_00001.png ... (default: none "
                        "copied; place them there)")
    p.add_argument("--intrinsics", type=Path, default=None, metavar="FILE",
                   help="the colour camera's pinhole intrinsics (YAML/JSON: fx, fy, cx, cy, width, height; pixels, "
                        "OpenCV's pixel centres; default: the session's (or the plan's) sensor, the simulated D435 "
                        "1280 x 720 unless configured)")
    p.add_argument("--force", action="store_true", help="replace an existing output folder (an earlier export)")


def export_arguments(p) -> None:
    formats = p.add_subparsers(dest="format", required=True)
    moveit = formats.add_parser("moveit", help="MoveIt pose goals (YAML) in the robot's base frame")
    _plan_options(moveit, "FILE", "the YAML file to write")
    moveit.add_argument("--frame", default="base_link", help="the base frame's name (default: %(default)s)")
    moveit.add_argument("--force", action="store_true", help="replace an existing file (an earlier export)")
    moveit.set_defaults(func=_moveit)

    ros2 = formats.add_parser(
        "ros2", help="a ROS 2 bag (MCAP): the views as a PoseArray and a Path, and the static transform",
        description="A ROS 2 bag (rosbag2 format 8, MCAP storage; Humble reads it with "
                    "ros-humble-rosbag2-storage-mcap) of one message per topic: /tpvp/views "
                    "(geometry_msgs/PoseArray, the camera's pose at every view in execution order), /tpvp/route "
                    "(nav_msgs/Path, the same poses as the route) and /tf_static (FRAME -> tpvp_scan, the "
                    "base-from-scan transform), all latched. Camera axes x right, y down, z forward (OpenCV); metres.")
    _plan_options(ros2, "DIR", "the bag folder to write (metadata.yaml and <name>.mcap inside: what `ros2 bag play` "
                               "takes)")
    ros2.add_argument("--frame", default="map", help="the robot's frame the poses are in (default: %(default)s)")
    ros2.add_argument("--stamp", default="0", metavar="SECONDS",
                      help="the header stamp of every message, seconds since 1970, also their log time in the bag "
                           "(default: 0, the same on every run; tf2 reads a zero stamp as 'the latest transform'; "
                           "stamped 0, the messages are logged at 1 s)")
    ros2.add_argument("--force", action="store_true", help="replace an existing bag folder (an earlier export)")
    ros2.set_defaults(func=_ros2)

    nerfstudio = formats.add_parser(
        "nerfstudio", help="a session's captures as nerfstudio's transforms.json and sparse_pc.ply",
        description="A session's captures for nerfstudio (ns-train ... --data DIR): transforms.json (one frame per "
                    "capture: camera-to-world, OpenGL camera axes x right, y up, z backward; pinhole intrinsics "
                    "with the principal point in nerfstudio's pixel centres, tpvp's + 0.5) and sparse_pc.ply (the "
                    "session's fused model, grey, the initial points). World frame, metres.")
    _reconstruction_options(nerfstudio, "SESSION", "a tpvp session folder with captures", "the folder to write")
    nerfstudio.set_defaults(func=_nerfstudio)

    colmap = formats.add_parser(
        "colmap", help="a session's captures (or a plan's views) as a COLMAP text model with known poses",
        description="A COLMAP text model: cameras.txt (one PINHOLE camera, principal point in COLMAP's pixel "
                    "centres, tpvp's + 0.5), images.txt (per capture its world-to-camera pose, OpenCV camera "
                    "axes, and image name; no 2D points) and points3D.txt (the session's fused model, grey, no "
                    "tracks; empty for a plan). World frame, metres. For COLMAP's point_triangulator with known "
                    "poses, or pycolmap.Reconstruction(DIR).")
    _reconstruction_options(colmap, "SESSION_OR_PLAN", "a tpvp session folder with captures, or a plan.csv (or the "
                                                       "folder holding it): its views, in execution order",
                            "the model folder to write")
    colmap.set_defaults(func=_colmap)
