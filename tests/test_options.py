"""Every configuration option of every command changes the resolved configuration or is refused.

The options are read from the commands' parsers (``tpvp.cli.build_parser``) and mapped to their
keys through the one table, :data:`tpvp.cli_common.OPTIONS`; each is given a value other than its
default, and the configuration(s) the command would run with are resolved (nothing is planned).
An option given to a setting it does not apply to must be refused with one line.
"""

from __future__ import annotations

import argparse

import pytest

from tpvp.cli import EVERY, build_parser
from tpvp.cli_common import OPTION, OPTIONS, check_options_apply, config_overrides, resolved_config
from tpvp.commands.experiments import season_setup
from tpvp.commands.rows import row_config
from tpvp.config_loading import load_config, with_overrides
from tpvp.errors import TpvpError

#: A value other than the default, for each option of the table.
VALUES = {"--coverage-target": "0.9", "--replan-after": "2", "--organ-targets": "fruit=1.0",
          "--view-space": "sphere", "--initial-view": "8", "--scale": "native", "--radius": "0.5",
          "--up-axis": "+y", "--cover-resolution": "0.05", "--room": "room4"}


def _season(args):
    config, cases = season_setup(args)
    return [case.config(config) for case in cases]


def _session_plan(args):
    """``session plan`` applies its overrides to the session's configuration (plant or row)."""
    base = load_config(args.config)
    check_options_apply(args, base.setting, base.name)
    return [with_overrides(base, config_overrides(args))]


#: Command -> (the arguments it needs besides its options, the configurations it would run with,
#: the configurations to try it on: --config's values; for session plan, the session's).
COMMANDS = {
    ("demo",): ([], lambda a: [resolved_config(a)], ("paper", "paper-row")),
    ("plan",): (["--previous", "a.ply", "--current", "b.ply"], lambda a: [resolved_config(a)], ("paper", "paper-row")),
    ("config",): ([], lambda a: [resolved_config(a)], ("paper", "paper-row")),
    ("session", "start"): (["--previous", "a.ply", "--output", "s"], lambda a: [resolved_config(a)],
                           ("paper", "paper-row")),
    ("session", "plan"): (["s"], _session_plan, ("paper", "paper-row")),
    ("greenhouse",): ([], lambda a: [row_config(a)], ("paper-row",)),
    ("experiments", "plants"): ([], lambda a: [resolved_config(a)], ("paper", "paper-row")),
    ("experiments", "rows"): ([], lambda a: [row_config(a)], ("paper-row",)),
    ("experiments", "season"): (["--quick"], _season, ("paper", "paper-row")),
    ("experiments", "season", "--rows"): (["--quick", "--rows"], _season, ("paper-row",)),
}


def _leaves(parser, path=()):
    subparsers = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    if not subparsers:
        yield path, parser
    for action in subparsers:
        for name, sub in action.choices.items():
            yield from _leaves(sub, (*path, name))


def _option_of(action):
    """The table's row of a parser action (``--replan-after`` of the season: its sweep), or None."""
    return next((OPTION[s] for s in action.option_strings if s in OPTION), None)


#: Commands whose options of the table's names set another configuration than the planner's.
OWN_CONFIGURATION = {("render",): "--view-space sets tpvp.simulate.render_demo.RenderDemoConfig, its own"}
PARSERS = {path: p for path, p in _leaves(build_parser(EVERY)) if path not in OWN_CONFIGURATION}
DECLARED = {path: [o for o in map(_option_of, parser._actions) if o is not None] for path, parser in PARSERS.items()}
CASES = [(command, named, option.flag)
         for command, (_, _, configs) in COMMANDS.items()
         for named in configs
         for option in DECLARED[command[:2] if command[-1].startswith("--") else command]]


def test_every_command_with_a_configuration_option_is_resolved_here():
    assert {path for path, options in DECLARED.items() if options} == {c for c in COMMANDS if not c[-1].startswith("--")}
    assert set(VALUES) == {option.flag for option in OPTIONS}


def test_every_option_is_declared_by_some_command_and_organ_targets_once_in_the_table():
    assert {o.flag for options in DECLARED.values() for o in options} == {o.flag for o in OPTIONS}
    assert [o.flag for o in OPTIONS].count("--organ-targets") == 1


def _resolve(command, named, *more):
    needs, resolve, _ = COMMANDS[command]
    words = [w for w in command if not w.startswith("-")]
    config = [] if command == ("session", "plan") else ["--config", named]
    args = build_parser(EVERY).parse_args([*words, *needs, *config, *more])
    if command == ("session", "plan"):
        args.config = named  # the session's configuration
    return resolve(args)


@pytest.mark.parametrize("command, named, flag", CASES, ids=[f"{' '.join(c)}-{n}-{f}" for c, n, f in CASES])
def test_an_option_changes_the_configuration_or_is_refused_with_one_line(command, named, flag):
    try:
        default = _resolve(command, named)
    except TpvpError:
        pytest.skip(f"{' '.join(command)} does not run with --config {named}")
    setting = default[0].setting
    try:
        given = _resolve(command, named, flag, VALUES[flag])
    except TpvpError as exc:
        assert "\n" not in str(exc) and str(exc)
        return
    assert setting in OPTION[flag].settings, f"{flag} applies to {OPTION[flag].settings}, yet ran on a {setting}"
    assert given != default, f"{' '.join(command)} {flag} {VALUES[flag]} changed no configuration"


@pytest.mark.parametrize("named, more, refusal", [
    ("paper-row", ["--organ-targets", "fruit=1.0"], "--organ-targets applies to individual plants"),
    ("paper-row", ["--set", "selection.organ_targets=fruit=1.0"], "organ targets need a plant's organ labels"),
    ("paper-row", ["--scale", "native"], "configuration 'paper-row' plans greenhouse rows"),
])
def test_an_option_for_plants_is_refused_for_rows(named, more, refusal):
    with pytest.raises(TpvpError, match=refusal):
        _resolve(("config",), named, *more)


def test_the_season_target_has_one_source():
    default = _resolve(("experiments", "season"), "paper")
    assert {c.selection.coverage_target for c in default} == {0.98}  # the season's own default
    for more in (["--coverage-target", "0.9"], ["--set", "selection.coverage_target=0.9"]):
        assert {c.selection.coverage_target for c in _resolve(("experiments", "season"), "paper", *more)} == {0.9}
    assert {c.selection.coverage_target
            for c in _resolve(("experiments", "season"), "paper", "--set", "selection.coverage_target=1.0")} == {1.0}
    with pytest.raises(TpvpError, match="the season sets it per case from --replan-after"):
        _resolve(("experiments", "season"), "paper", "--set", "selection.replan_after=1")
    with pytest.raises(TpvpError, match="--view-spaces applies to the plants' season"):
        _resolve(("experiments", "season", "--rows"), "paper-row", "--view-spaces", "sphere")
    with pytest.raises(TpvpError, match="--rooms applies to the rows' season"):
        _resolve(("experiments", "season"), "paper", "--rooms", "room1")


def test_the_season_sweeps_replan_after_as_the_plan_commands_set_it():
    """--replan-after: one K for a plan, several for the season (one run each); the same key."""
    configs = _resolve(("experiments", "season"), "paper", "--replan-after", "0", "2")
    assert sorted({c.selection.replan_after for c in configs}) == [0, 2]
    assert _resolve(("config",), "paper", "--replan-after", "2")[0].selection.replan_after == 2
