"""``tpvp export``: a plan handed to a robot's software."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tpvp.io import atomic_write_text
from tpvp.pipeline.robot import moveit_goals, read_plan, read_transform


def _moveit(args) -> int:
    table = read_plan(args.plan)
    matrix = read_transform(args.base_from_scan) if args.base_from_scan else np.eye(4)
    written = atomic_write_text(args.output, moveit_goals(table, args.frame, matrix, str(args.plan)))
    print(f"wrote {written} ({len(table)} pose goals in frame {args.frame!r})")
    return 0


def export_arguments(p) -> None:
    formats = p.add_subparsers(dest="format", required=True)
    moveit = formats.add_parser("moveit", help="MoveIt pose goals (YAML) in the robot's base frame")
    moveit.add_argument("plan", type=Path, help="a plan.csv (or the folder holding it) of tpvp plan or tpvp session")
    moveit.add_argument("--base-from-scan", type=Path, default=None, metavar="FILE",
                        help="JSON or YAML 4x4 rigid transform taking the plan's (scan) frame into the robot's base "
                             "frame, metres (default: the identity)")
    moveit.add_argument("--frame", default="base_link", help="the base frame's name (default: %(default)s)")
    moveit.add_argument("--output", type=Path, required=True, help="the YAML file to write")
    moveit.set_defaults(func=_moveit)
