"""``tpvp config``: the resolved configuration as YAML."""

from __future__ import annotations

from tpvp.cli_common import case_options, resolved_config
from tpvp.config_loading import config_yaml, derived_table


def _show_config(args) -> int:
    config = resolved_config(args)
    print(config_yaml(config, f"resolved configuration {config.name!r} (setting: {config.setting})"), end="")
    if args.derived:
        print("# derived parameters (unless set explicitly):")
        for key, rule in derived_table(config.setting):
            print(f"#   {key} = {rule}")
    return 0


def config_arguments(p) -> None:
    case_options(p, None)
    p.add_argument("--derived", action="store_true", help="also list the derived parameters and their rules")
    p.set_defaults(func=_show_config)
