"""What the command lines share: the configuration options and their resolution, one-line warnings.

:data:`OPTIONS` is the one table from a command-line option to its configuration key: every
command declares its configuration options from it (:func:`add_config_options`) and turns them
into overrides with :func:`config_overrides`; an option given to a setting it does not apply to is
refused with one line (:func:`check_options_apply`), never ignored.

A light module (no experiment is imported), so that ``tpvp session`` loads only what it runs.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from typing import Callable

from tpvp.config_loading import NAMED, load_config, parse_overrides
from tpvp.scene.config import SCALES, UP_AXES
from tpvp.errors import ConfigError, TpvpError
from tpvp.scene.boxes import ROOMS
from tpvp.viewspace.space import get_view_space, view_space_choices

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


REPLAN_AFTER_HELP = ("re-plan the rest of the plan from the captures after every K planned views "
                     "(selection.replan_after; 0: plan once, the paper's; default: the configuration's, 0)")
ORGAN_TARGETS_HELP = ("the share of each organ's predicted planning voxels the plan must see, e.g. "
                      "fruit=1.0,leaf=0.95 (organs: unknown, stem, leaf, petiole, peduncle, flower, fruit; the "
                      "others keep --coverage-target's share); needs labelled scans (--labels) "
                      "(selection.organ_targets)")
#: What each setting plans, in the refusal of an option that does not apply to it.
SETTING_WORDS = {"plant": "individual plants", "row": "greenhouse rows"}


def _index_or_name(value: str):
    """``--initial-view``: an index (``17``) or a view's name (``near_horizontal``)."""
    return int(value) if value.lstrip("-").isdigit() else value


def view_space_arg(value: str) -> str:
    try:
        get_view_space(value)  # one clear error line for an unknown name or a bad file
    except TpvpError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return value


@dataclass(frozen=True)
class ConfigOption:
    """One command-line option that sets one configuration key (a row of :data:`OPTIONS`).

    ``settings``: the settings whose plans use the key (``plant``, ``row``); given to another, the
    option is refused. ``help``: the text, or a function giving it (computed when the option is
    declared). ``default``: None (the configuration's value stands unless the option is given), or
    a value set like a given one (``--room``)."""

    flag: str
    key: str
    settings: tuple[str, ...]
    help: str | Callable[[], str]
    type: Callable | None = None
    metavar: str | None = None
    choices: tuple | None = None
    default: object = None

    @property
    def dest(self) -> str:
        return self.flag.lstrip("-").replace("-", "_")

    def add_to(self, p, nargs=None, dest=None, default=None, help=None) -> None:
        """Declare the option on parser ``p``; ``nargs``/``dest``/``default``/``help``: a sweep's
        (several values, one run each: ``tpvp experiments season --replan-after 0 1``)."""
        extra = {"nargs": nargs, "dest": dest} if nargs else {}
        p.add_argument(self.flag, default=self.default if default is None else default, type=self.type,
                       metavar=self.metavar, choices=self.choices,
                       help=help or (self.help() if callable(self.help) else self.help), **extra)


#: Option -> configuration key: every command's configuration options, declared once.
OPTIONS = (
    ConfigOption("--coverage-target", "selection.coverage_target", ("plant", "row"), COVERAGE_TARGET_HELP,
                 float, "FRACTION"),
    ConfigOption("--replan-after", "selection.replan_after", ("plant",), REPLAN_AFTER_HELP, int, "K"),
    ConfigOption("--organ-targets", "selection.organ_targets", ("plant",), ORGAN_TARGETS_HELP,
                 metavar="ORGAN=SHARE,..."),
    ConfigOption("--view-space", "view_space", ("plant", "row"),
                 lambda: f"candidate views: {view_space_choices()} (default: the configuration's, hemisphere)",
                 view_space_arg, "SPACE"),
    ConfigOption("--initial-view", "initial_view", ("plant",),
                 "initial view: an index or near_horizontal (17), oblique (8), near_top (21) "
                 "(default: the configuration's, 17)", _index_or_name, "INDEX|NAME"),
    ConfigOption("--scale", "scene.scale", ("plant",),
                 "normalised: the paper's protocol, plant scaled to a 0.24 m largest side; native: plan "
                 "at the plant's true size with --radius (default: normalised)", choices=SCALES),
    ConfigOption("--radius", "scene.radius", ("plant",),
                 "view-sphere radius in metres (native: around the real plant, default 0.4; "
                 "normalised: default the view space's 0.4)", float, "M"),
    ConfigOption("--up-axis", "scene.up_axis", ("plant",),
                 "the scan axis that points up; the plant is turned so that it becomes +Z (default: +z)",
                 choices=UP_AXES),
    ConfigOption("--cover-resolution", "selection.cover_resolution", ("plant", "row"),
                 "covering voxel of the set cover (paper: 0.10, 0.05, 0.04, 0.03; default: the "
                 "configuration's, 0.04)", float, "M"),
    ConfigOption("--room", "view_space", ("row",), "(default: %(default)s)", choices=ROOMS, default=ROOMS[0]),
)
OPTION = {option.flag: option for option in OPTIONS}


def add_config_options(p, *flags: str) -> None:
    """Declare the options ``flags`` of :data:`OPTIONS` on parser ``p``, in that order."""
    for flag in flags:
        OPTION[flag].add_to(p)


def config_overrides(args) -> dict:
    """The dotted-key overrides of ``args``: each option of :data:`OPTIONS` the command declares
    that is given (or has a default of its own), then ``--set`` (which wins)."""
    overrides = {option.key: value for option in OPTIONS
                 if (value := getattr(args, option.dest, None)) is not None}
    overrides.update(parse_overrides(getattr(args, "set", None)))
    return overrides


def check_options_apply(args, setting: str, name: str) -> None:
    """Refuse, with one line, an option of ``args`` given to a configuration whose setting it does
    not apply to (``--scale`` with ``paper-row``): never ignored."""
    for option in OPTIONS:
        value = getattr(args, option.dest, None)
        if value is not None and value != option.default and setting not in option.settings:
            raise ConfigError(f"{option.flag} applies to {' and '.join(SETTING_WORDS[s] for s in option.settings)}; "
                              f"configuration {name!r} plans {SETTING_WORDS[setting]}")


def resolved_config(args, source=None, extra=None):
    """The resolved configuration: ``source`` (default: --config), ``extra`` overrides (a preset
    such as ``--quick``'s), the options of :data:`OPTIONS` given, then --set overrides."""
    source = args.config if source is None else source
    base = load_config(source)  # its setting, to refuse an option that does not apply to it
    check_options_apply(args, base.setting, base.name)
    config = load_config(source, {**(extra or {}), **config_overrides(args)})

    if config.setting == "plant":  # a row has no initial view: its passive sweep starts it
        config.space.view_index(config.initial_view)  # refuse before any work
    return config


def configuration_options(p, output, named: str = "paper"):
    """--output, --config, --set and --coverage-target: the same for plants and rows."""
    if output is not None:
        p.add_argument("--output", default=output, help="output folder (default: %(default)s)")
    p.add_argument("--config", default=named, metavar="NAME|FILE",
                   help=f"named configuration ({', '.join(n for n, (s, _) in NAMED.items() if s == NAMED[named][0])}) "
                        f"or a YAML file, e.g. a run's config.yaml (default: %(default)s)")
    listed = "tpvp config --derived" if named == "paper" else f"tpvp config --config {named} --derived"
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help=f"override one configuration key, e.g. --set registration.embedded_deformation.iterations=100 "
                        f"(repeatable; `{listed}` lists the keys)")
    add_config_options(p, "--coverage-target")


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
    add_config_options(p, "--replan-after", "--organ-targets", "--view-space", "--initial-view", "--scale", "--radius",
                       "--up-axis")
