"""``python -m data_tools``: the data tools' command line, after the dependency check of
``python -m tpvp`` (one line naming a missing package, exit status 2, no traceback)."""

import sys

from tpvp.__main__ import run_checked


def _load_main():
    from data_tools.cli import main

    return main


if __name__ == "__main__":
    sys.exit(run_checked("data_tools", _load_main, exiting=True))
