"""``tpvp session start|add|plan|export``: a real session on the command line (docs/session.md).

Parsed here, without the experiments: ``python -m tpvp session ...`` loads only this module and the
session package, so a step costs little more than its own work.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from tpvp import __version__
from tpvp.cli_common import COVERAGE_TARGET_HELP, case_options, print_warnings, resolved_config
from tpvp.config import parse_overrides
from tpvp.errors import TpvpError, install_warning_format, run_command
from tpvp.io import read_point_cloud
from tpvp.scene.boxes import ROOMS
from tpvp.scene.simulator import NATIVE_RADIUS
from tpvp.sensor.camera import D435
from tpvp.session import Session, read_depth, read_intrinsics, read_pose_file


def add_session_parser(sub) -> None:
    session = sub.add_parser("session", help="plan a real session: the previous model and the robot's first "
                                             "captures, no ground truth (start, add, plan, export)")
    steps = session.add_subparsers(dest="step", required=True)
    start = steps.add_parser("start", help="fix the world frame and the candidate views from the previous model; "
                                           "print the first pose to capture")
    start.add_argument("--previous", required=True, type=Path, help="the previous session's model (ply/pcd/xyz/...)")
    start.add_argument("--units", default="auto", choices=["auto", "m", "mm"],
                       help="units of the previous model and of every capture (default: %(default)s)")
    case_options(start, None, frontier=False)
    start.add_argument("--output", required=True, type=Path, help="the new session folder")
    start.set_defaults(func=_session_start)
    add = steps.add_parser("add", help="fuse a capture (a cloud in the world frame, or a depth image) and print "
                                       "the next pose")
    add.add_argument("folder", type=Path, help="the session folder")
    what = add.add_mutually_exclusive_group(required=True)
    what.add_argument("--cloud", type=Path, help="a captured cloud in the world frame (the previous model's)")
    what.add_argument("--depth", type=Path, help="a depth image: .npy (metres) or 16-bit .png (millimetres)")
    add.add_argument("--units", default=None, choices=["auto", "m", "mm"],
                     help="units of the cloud (default: those the previous model was read in)")
    add.add_argument("--intrinsics", type=Path, default=None,
                     help="YAML/JSON with fx, fy, cx, cy, width, height (pixels), optional depth_scale (m per unit); "
                          "default: the simulated D435 1280 x 720")
    add.add_argument("--pose", default=None, metavar="VIEW|FILE",
                     help="where it was captured: a candidate view (index or name), or a pose file (JSON position + "
                          "look_at, or a plan.csv row; snapped to the nearest candidate) (default: the pose the "
                          "session asked for)")
    add.set_defaults(func=_session_add)
    plan = steps.add_parser("plan", help="plan today's views on what was captured (writes FOLDER/plan/)")
    plan.add_argument("folder", type=Path, help="the session folder")
    plan.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                      help="override one configuration key for this plan")
    plan.add_argument("--coverage-target", default=None, type=float, metavar="FRACTION", help=COVERAGE_TARGET_HELP)
    plan.set_defaults(func=_session_plan)
    export = steps.add_parser("export", help="write today's fused model (the next session's --previous)")
    export.add_argument("folder", type=Path, help="the session folder")
    export.add_argument("--model", required=True, type=Path, help="the model file to write (.ply/.pcd/.xyz)")
    export.set_defaults(func=_session_export)


def _session_start(args) -> int:
    if args.scale == "normalised":
        raise TpvpError("--scale normalised: a real session plans at the plant's true size (the candidate views "
                        "are metres around it); leave --scale out")
    if args.view_space in ROOMS and args.config == "paper":
        args.config = "paper-row"  # a room's view space is a greenhouse row's
    config = resolved_config(args)
    previous, units = read_point_cloud(args.previous, units=args.units, return_units=True)
    session = Session.start(args.output, previous, config, str(args.previous), units=units.used)
    positions, _ = session.views()
    where = (f"{config.view_space}, the room's frame" if session.kind == "row" else
             f"{config.view_space}, {session.config.scene.radius or NATIVE_RADIUS:g} m around the plant")
    print(f"{args.previous.name}: units: {units}; session {args.output}: {len(positions)} views to capture first or "
          f"plan from ({where}); world frame = the previous model's")
    print(session.request().describe())
    return 0


def _session_add(args) -> int:
    session = Session.open(args.folder)
    pose = read_pose_file(args.pose) if args.pose is not None and Path(args.pose).is_file() else None
    view, distance = session.resolve_view(None if pose is not None else args.pose, pose)
    if pose is not None and distance > 1e-3:
        print_warnings([f"{args.pose}: the pose is {distance:.3g} m from candidate view {view}, the nearest; "
                         f"the capture is taken as view {view}"])
    if args.cloud is not None:
        points = read_point_cloud(args.cloud, units=args.units or session.state["units"])
        record = session.add(points, view, str(args.cloud))
    else:
        intrinsics, depth_scale = read_intrinsics(args.intrinsics) if args.intrinsics else (D435, None)
        record = session.add_depth(read_depth(args.depth, depth_scale), intrinsics, view, str(args.depth))
    print(f"capture {len(session.captures)}: view {record['view']}, {record['points']:,} points "
          f"({record['points_kept']:,} near the plant), {record['voxels']:,} voxels")
    print(session.request().describe())
    return 0


def _session_plan(args) -> int:
    session = Session.open(args.folder)
    overrides = parse_overrides(args.set)
    if args.coverage_target is not None:
        overrides["selection.coverage_target"] = args.coverage_target
    result = session.plan(overrides)
    planned = session.state["plan"]["planned_views"]
    print(f"  views (captures included)         {result.n_views} ({result.n_views - len(planned)} captured, "
          f"{len(planned)} planned: {_views_listed(planned)})")
    print(f"  path length                       {result.path_length / session.scene.scan_scale:.3f} m (world frame)")
    timings = result.timings
    print("  time: " + ", ".join(f"{k} {timings[k]:.2f} s" for k in ("registration", "inflation", "visibility",
                                                                      "selection", "path")))
    print(f"wrote {args.folder / 'plan'}/ (plan.csv and plan.json in the world frame, results, plan.png, "
          f"recording.rrd); {session.request().describe()}")
    print_warnings(result.warnings)
    return 0


def _views_listed(views, shown: int = 12) -> str:
    return ", ".join(map(str, views[:shown])) + (f", ... ({len(views)} in all)" if len(views) > shown else "")


def _session_export(args) -> int:
    path = Session.open(args.folder).export(args.model)
    print(f"wrote {path} (today's fused model, world frame)")
    return 0


def main(argv=None) -> int:
    """``tpvp session ...`` alone (the full ``tpvp`` parser holds the same subcommand)."""
    install_warning_format("tpvp")
    parser = argparse.ArgumentParser(prog="tpvp")
    parser.add_argument("--version", action="version", version=f"tpvp {__version__}")
    add_session_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    return run_command(args, f"tpvp {args.command}")
