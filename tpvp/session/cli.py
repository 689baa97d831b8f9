"""``tpvp session start|add|plan|export|check``: a real session on the command line (docs/session.md).

Loaded alone by :mod:`tpvp.cli`, without the experiments: a step costs little more than its own work. Each step holds the session
folder from its read to its commit (another command waits up to ``--wait`` seconds, then exit 3),
and is complete once committed: a Ctrl-C or SIGTERM after the commit is reported, not obeyed
(exit 0, the step's own lines printed).
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import signal
import sys
from pathlib import Path

from tpvp.cli_common import (add_config_options, case_options, check_options_apply, config_overrides, print_warnings,
                              resolved_config)
from tpvp.errors import InputFileError, TpvpError
from tpvp.io import read_point_cloud
from tpvp.io.publish import RunInterrupted, armed_step, late_signals, staged_file
from tpvp.io.units import plant_size_warning
from tpvp.scene.boxes import ROOMS
from tpvp.scene.frame import NATIVE_RADIUS
from tpvp.scene.organs import LABEL_KINDS, organ_codes
from tpvp.sensor.camera import D435
from tpvp.session import Session, read_depth, read_intrinsics, read_pose_file
from tpvp.session.check import repair_folder

#: Seconds a step waits for another command on the same session folder (``--wait``).
WAIT_S = 60.0


def session_arguments(session) -> None:
    steps = session.add_subparsers(dest="step", required=True)
    start = steps.add_parser("start", help="fix the world frame and the candidate views from the previous model; "
                                           "print the first pose to capture")
    start.add_argument("--previous", required=True, type=Path, help="the previous session's model (ply/pcd/xyz/...)")
    start.add_argument("--units", default="auto", choices=["auto", "m", "mm"],
                       help="units of the previous model and of every capture (default: %(default)s)")
    case_options(start, None, frontier=False)
    start.add_argument("--drop-invalid", action="store_true",
                       help="drop points with NaN or infinite coordinates instead of refusing the model")
    start.add_argument("--labels", default="none", choices=["none", *LABEL_KINDS],
                       help="what the previous model's point labels mean (organ, pheno4d, generated-row): its organs "
                            "follow the registration, for --organ-targets (default: %(default)s)")
    start.add_argument("--output", required=True, type=Path, help="the new session folder")
    _wait_option(start)
    start.set_defaults(func=_session_start)
    add = steps.add_parser("add", help="fuse a capture (a cloud in the world frame, or a depth image) and print "
                                       "the next pose")
    add.add_argument("folder", type=Path, help="the session folder")
    what = add.add_mutually_exclusive_group(required=True)
    what.add_argument("--cloud", type=Path, help="a captured cloud in the world frame (the previous model's)")
    what.add_argument("--depth", type=Path, help="a depth image: .npy (metres) or 16-bit .png (millimetres)")
    add.add_argument("--units", default=None, choices=["auto", "m", "mm"],
                     help="units of the cloud (default: those the previous model was read in)")
    add.add_argument("--drop-invalid", action="store_true",
                     help="drop points with NaN or infinite coordinates (a camera's invalid pixels) instead of "
                          "refusing the cloud; the count is printed")
    add.add_argument("--intrinsics", type=Path, default=None,
                     help="YAML/JSON with fx, fy, cx, cy, width, height (pixels), optional depth_scale (m per unit); "
                          "default: the simulated D435 1280 x 720")
    add.add_argument("--pose", default=None, metavar="VIEW|FILE",
                     help="where it was captured: a candidate view (index or name), or a pose file (JSON position + "
                          "look_at, or a plan.csv row; snapped to the nearest candidate) (default: the pose the "
                          "session asked for)")
    _wait_option(add)
    add.set_defaults(func=_session_add)
    plan = steps.add_parser("plan", help="plan today's views on what was captured (writes FOLDER/plan/)")
    plan.add_argument("folder", type=Path, help="the session folder")
    plan.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                      help="override one configuration key for this plan")
    add_config_options(plan, "--coverage-target", "--organ-targets", "--replan-after")
    _wait_option(plan)
    plan.set_defaults(func=_session_plan)
    export = steps.add_parser("export", help="write today's fused model (the next session's --previous)")
    export.add_argument("folder", type=Path, help="the session folder")
    export.add_argument("--model", required=True, type=Path, help="the model file to write (.ply/.pcd/.xyz)")
    export.add_argument("--force", action="store_true", help="replace an existing model file (an earlier export)")
    _wait_option(export)
    export.set_defaults(func=_session_export)
    check = steps.add_parser("check", help="list every problem of a session folder (files gone or damaged, "
                                           "session.json edited); --repair fixes what can be fixed safely")
    check.add_argument("folder", type=Path, help="the session folder")
    check.add_argument("--repair", action="store_true",
                       help="drop the captures whose files are gone or damaged, remove files no capture names, "
                            "drop a plan whose record or files are gone or damaged; says what it does first")
    _wait_option(check)
    check.set_defaults(func=_session_check)


def _wait_option(p) -> None:
    p.add_argument("--wait", type=_seconds, default=WAIT_S, metavar="SECONDS",
                   help="how long to wait for another command on the same session folder to finish; then exit "
                        "status 3 (default: %(default)g; 0 refuses at once)")


def _seconds(value: str) -> float:
    try:
        seconds = float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{value!r} is not a number of seconds") from None
    if not 0 <= seconds < float("inf"):
        raise argparse.ArgumentTypeError(f"{value!r}: give 0 or more seconds")
    return seconds


@contextlib.contextmanager
def _held(args):
    """The session of ``args.folder``, held for the step (:meth:`Session.held`); the step is armed:
    a stop signal before its commit leaves the folder as it was, one after it is only noted."""
    def waiting():
        print(f"tpvp session {args.step}: {args.folder} is being written by another run; waiting for it (at most "
              f"{args.wait:g} s)", file=sys.stderr, flush=True)
    try:
        with armed_step(), Session.held(args.folder, args.wait, waiting) as session:
            yield session
    except KeyboardInterrupt as exc:
        if isinstance(exc, RunInterrupted):
            raise
        raise RunInterrupted(args.folder, published=False) from None


def _say_late_signals(args, done: str) -> None:
    """A stop signal after the commit did not stop the step: say so, once."""
    arrived = late_signals()
    if arrived:
        name = signal.Signals(arrived[0]).name
        print(f"tpvp session {args.step}: {name} received after {done}; the step is complete", file=sys.stderr)


def _session_start(args) -> int:
    if args.scale == "normalised":
        raise TpvpError("--scale normalised: a real session plans at the plant's true size (the candidate views "
                        "are metres around it); leave --scale out")
    if args.view_space in ROOMS and args.config == "paper":
        args.config = "paper-row"  # a room's view space is a greenhouse row's
    config = resolved_config(args)
    previous, labels, units = read_point_cloud(args.previous, units=args.units, return_units=True,
                                               return_labels=True, drop_invalid=args.drop_invalid)
    organs = None
    if args.labels != "none":
        if labels is None:
            raise TpvpError(f"{args.previous}: --labels {args.labels}: the model has no label per point")
        organs = organ_codes(labels, args.labels)
    if config.setting == "plant":
        print_warnings([w for w in [plant_size_warning(previous, units, str(args.previous))] if w])
    with armed_step():
        session = Session.start(args.output, previous, config, str(args.previous), units=units.used, wait=args.wait,
                                previous_organs=organs)
    positions, _ = session.views()
    where = (f"{config.view_space}, the room's frame" if session.kind == "row" else
             f"{config.view_space}, {session.config.scene.radius or NATIVE_RADIUS:g} m around the plant")
    print(f"{args.previous.name}: units: {units}; session {args.output}: {len(positions)} views to capture first or "
          f"plan from ({where}); world frame = the previous model's")
    print(session.request().describe())
    _say_late_signals(args, f"session {args.output} was started")
    return 0


def _pose_argument(pose: str | None):
    """``(view or None, Pose or None)`` from ``--pose``: a pose file, else a view's index or name."""
    if pose is None:
        return None, None
    if Path(pose).is_file():
        return None, read_pose_file(pose)
    if Path(pose).suffix or os.sep in pose or Path(pose).exists():
        raise InputFileError(f"--pose {pose}: no such file (--pose is a pose file, or a candidate view's "
                             f"index or name)")
    return pose, None


def _session_add(args) -> int:
    with _held(args) as session:
        view, pose = _pose_argument(args.pose)
        view, distance = session.resolve_view(view, pose)
        if pose is not None and distance > 1e-3:
            print_warnings([f"{args.pose}: the pose is {distance:.3g} m from candidate view {view}, the nearest; "
                             f"the capture is taken as view {view}"])
        if args.cloud is not None:
            points = read_point_cloud(args.cloud, units=args.units or session.state["units"],
                                      drop_invalid=args.drop_invalid)
            record = session.add(points, view, str(args.cloud))
        else:
            intrinsics, depth_scale = read_intrinsics(args.intrinsics) if args.intrinsics else (D435, None)
            record = session.add_depth(read_depth(args.depth, depth_scale), intrinsics, view, str(args.depth))
        number = len(session.captures)
        print(f"capture {number}: view {record['view']}, {record['points']:,} points "
              f"({record['points_kept']:,} near the plant), {record['voxels']:,} voxels")
        print(session.request().describe())
    _say_late_signals(args, f"capture {number} was recorded")
    return 0


def _session_plan(args) -> int:
    overrides = config_overrides(args)
    with _held(args) as session:
        check_options_apply(args, session.config.setting, session.config.name)
        result = session.plan(overrides)
        captured = {c["view"] for c in session.captures}
        left = [v for v in session.state["plan"]["planned_views"] if v not in captured]
        if result.replans:
            step = result.replans[-1]
            print(f"  re-plan {len(result.replans)}: {step.line()}")
            if step.remaining_before == 0:  # the check of a plan whose views were all captured
                seen = (f"the captures see {100 * step.captured_coverage:.2f} % of the planning surface (the plan "
                        f"asks {100 * result.planning_target:.2f} %)")
                print(f"  {seen}: {step.views_added} view(s) added to close the gap" if step.views_added else
                      f"  {seen}: the plan's target holds, nothing to add")
        print(f"  views (captures included)         {result.n_views} ({result.n_views - len(left)} captured, "
              f"{len(left)} to capture: {_views_listed(left)})")
        if math.isfinite(result.predicted_coverage):
            from tpvp.setcover.miss_model import coverage_statement  # scipy: only a plan below 1

            print(f"  true coverage, as the plan expects "
                  f"{coverage_statement(result.predicted_coverage, result.predicted_coverage_lower)}")
        print(f"  path length                       {result.path_length / session.scene.scan_scale:.3f} m "
              f"(world frame)")
        timings = result.timings
        print("  time: " + ", ".join(f"{k} {timings[k]:.2f} s" for k in ("registration", "inflation", "visibility",
                                                                          "selection", "path")))
        print(f"wrote {args.folder / 'plan'}/ (plan.csv and plan.json in the world frame, results, plan.png, "
              f"recording.rrd); {session.request().describe()}")
    print_warnings(result.warnings)
    _say_late_signals(args, "the plan was written")
    return 0


def _views_listed(views, shown: int = 12) -> str:
    return ", ".join(map(str, views[:shown])) + (f", ... ({len(views)} in all)" if len(views) > shown else "")


def _session_export(args) -> int:
    with _held(args) as session, staged_file(args.model, inputs=[args.folder], force=args.force,
                                             what="model file") as staged:
        session.export(staged)
    print(f"wrote {args.model} (today's fused model, world frame)")
    return 0


def _session_check(args) -> int:
    """List the folder's problems; with ``--repair``, say what will be done, do it, list what is left."""
    with armed_step(), Session.locked(args.folder, args.wait):
        problems = Session.problems(args.folder)
        for problem in problems:
            print(f"problem: {problem.line(args.folder)}")
        repairable = [p for p in problems if p.repair is not None]
        if args.repair and repairable:
            for problem in repairable:
                print(f"repair: {problem.repair}")
            repair_folder(args.folder, repairable)
            problems = Session.problems(args.folder)
            for problem in problems:
                print(f"left: {problem.line(args.folder)}")
        session = None if problems else Session.open(args.folder)
    if session is None:
        hint = (f"; `tpvp session check {args.folder} --repair` repairs {len(repairable)} of them"
                if repairable and not args.repair else "")
        print(f"tpvp session check: error: {args.folder}: {len(problems)} problem{'s' * (len(problems) > 1)}{hint}",
              file=sys.stderr)
        return 2
    plan, captures = session.state.get("plan"), len(session.captures)
    planned = f"a plan of {len(plan['planned_views'])} views" if plan else "no plan yet"
    print(f"{args.folder}: a {session.kind} session, {captures} capture{'s' * (captures != 1)}, {planned}; "
          f"no problem found")
    print(session.request().describe())
    _say_late_signals(args, "the folder was repaired")
    return 0
