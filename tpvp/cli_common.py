"""What the command lines share: the configuration options and their resolution, one-line warnings.

A light module (no experiment is imported), so that ``tpvp session`` loads only what it runs.
"""

from __future__ import annotations

import argparse
import sys

from tpvp.config import SCALES, UP_AXES, load_config, parse_overrides
from tpvp.errors import TpvpError
from tpvp.viewspace import get_view_space, view_space_choices

# One rule for plants and rows (selection.coverage_target, SelectionConfig.planning_target).
COVERAGE_TARGET_HELP = ("true coverage of today's plants to aim for, e.g. 0.98: the fewest views that see "
                        "1 - r x (1 - target) of the predicted planning surface (exact partial set cover; r per "
                        "view space, selection.planning_miss_ratio: 0.5 hemisphere, 0.25 sphere and rooms); "
                        "1.0 = the paper's full set cover (default: the configuration's, 1.0)")


def print_warnings(warnings) -> None:
    for warning in warnings:
        print(f"tpvp: warning: {warning}", file=sys.stderr)


def print_rows(rows, folder, files: str) -> None:
    """A case's figures as aligned ``name  value`` lines, then what was written where."""
    width = max(len(k) for k, _ in rows)
    for key, value in rows:
        print(f"  {key:<{width}}  {value}")
    print(f"wrote {folder}/ ({files})")


def resolved_config(args):
    """The resolved configuration: --config, then the dedicated options, then --set overrides."""
    overrides = {}
    initial = getattr(args, "initial_view", None)
    if initial is not None and initial.lstrip("-").isdigit():
        initial = int(initial)
    for key, value in (("view_space", getattr(args, "view_space", None)), ("initial_view", initial),
                       ("scene.scale", getattr(args, "scale", None)), ("scene.radius", getattr(args, "radius", None)),
                       ("scene.up_axis", getattr(args, "up_axis", None)),
                       ("selection.coverage_target", getattr(args, "coverage_target", None)),
                       ("selection.replan_after", getattr(args, "replan_after", None)),
                       ("selection.organ_targets", getattr(args, "organ_targets", None))):
        if value is not None:
            overrides[key] = value
    overrides.update(parse_overrides(args.set))
    config = load_config(args.config, overrides)

    if config.setting == "plant":  # a row has no initial view: its passive sweep starts it
        get_view_space(config.view_space).view_index(config.initial_view)  # refuse before any work
    return config


def configuration_options(p, output, named: str = "paper"):
    """--output, --config, --set and --coverage-target: the same for plants and rows."""
    if output is not None:
        p.add_argument("--output", default=output, help="output folder (default: %(default)s)")
    p.add_argument("--config", default=named, metavar="NAME|FILE",
                   help=f"named configuration ({named}) or a YAML file, e.g. a run's config.yaml (default: %(default)s)")
    listed = "tpvp config --derived" if named == "paper" else f"tpvp config --config {named} --derived"
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help=f"override one configuration key, e.g. --set registration.embedded_deformation.iterations=100 "
                        f"(repeatable; `{listed}` lists the keys)")
    p.add_argument("--coverage-target", default=None, type=float, metavar="FRACTION", help=COVERAGE_TARGET_HELP)


def replan_option(p) -> None:
    p.add_argument("--replan-after", default=None, type=int, metavar="K",
                   help="re-plan the rest of the plan from the captures after every K planned views "
                        "(selection.replan_after; 0: plan once, the paper's; default: the configuration's, 0)")


def view_space_arg(value: str) -> str:
    try:
        get_view_space(value)  # one clear error line for an unknown name or a bad file
    except TpvpError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return value


def case_options(p, output, case_options=True, frontier=True) -> None:
    """The options of a single-plant case: the configuration ones, then (``case_options``) the
    frontier, the view space, the initial view, the scale, the radius and the up axis."""
    configuration_options(p, output)
    if not case_options:
        return
    if frontier:
        p.add_argument("--frontier", action="store_true",
                       help="also the coverage-effort frontier of this case: the plan for targets 0.90 ... 1.0 "
                            "beside the exact optimum with perfect knowledge (frontier.csv, frontier.png; "
                            "about 10-60 s more)")
    replan_option(p)
    p.add_argument("--organ-targets", default=None, metavar="ORGAN=SHARE,...",
                   help="the share of each organ's predicted planning voxels the plan must see, e.g. "
                        "fruit=1.0,leaf=0.95 (organs: unknown, stem, leaf, petiole, peduncle, flower, fruit; the "
                        "others keep --coverage-target's share); needs labelled scans (--labels) "
                        "(selection.organ_targets)")
    p.add_argument("--view-space", default=None, type=view_space_arg, metavar="SPACE",
                   help=f"candidate views: {view_space_choices()} (default: the configuration's, hemisphere)")
    p.add_argument("--initial-view", default=None, metavar="INDEX|NAME",
                   help="initial view: an index or near_horizontal (17), oblique (8), near_top (21) "
                        "(default: the configuration's, 17)")
    p.add_argument("--scale", default=None, choices=SCALES,
                   help="normalised: the paper's protocol, plant scaled to a 0.24 m largest side; native: plan "
                        "at the plant's true size with --radius (default: normalised)")
    p.add_argument("--radius", default=None, type=float, metavar="M",
                   help="view-sphere radius in metres (native: around the real plant, default 0.4; "
                        "normalised: default the view space's 0.4)")
    p.add_argument("--up-axis", default=None, choices=UP_AXES,
                   help="the scan axis that points up; the plant is turned so that it becomes +Z (default: +z)")
