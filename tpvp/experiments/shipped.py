"""The paper's full-protocol result rows, shipped with tpvp (``tpvp/data/results/``).

Every paper table is drawn from raw result rows, one or a few per (case, method). The full
protocol's rows are small, so they are kept in the repository, one Parquet file per protocol
(:data:`PROTOCOLS`: what a notebook's tables are made of), with the commit, command, date and
machine that wrote each in ``provenance.json``. Reader's mode on a fresh clone draws the paper's
tables from them in seconds, without computing a case; a notebook names its protocol
(``"table1"``) and never defines one.

``python -m tpvp.experiments.shipped refresh [NAME ...]`` recomputes them (the experiment cache
answers the tasks it holds) after a change to the method; ``python -m tpvp.experiments.shipped``
lists what is shipped.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import pandas as pd

from tpvp.config import make_config
from tpvp.errors import ConfigError, run_command
from tpvp.experiments import ablation, plants, rows, season, species
from tpvp.experiments.runner import cached_experiments, experiment_cache
from tpvp.io import atomic_write_bytes, atomic_write_text
from tpvp.parallel import run_cases

ROOT = Path(__file__).resolve().parent.parent.parent
SHIPPED = ROOT / "tpvp" / "data" / "results"
PROVENANCE = "provenance.json"
#: The references of a generated row Tables V-VI are shipped for (docs/greenhouse.md).
REFERENCES = ("handheld", "complete", "candidates")


@dataclass(frozen=True)
class Protocol:
    """What one notebook's tables are made of: the ``setting``'s full cases (rows: of
    ``references``; ``first_case_only`` for the timing of one case) and ``methods``."""

    setting: str  # "plants", "rows", "season" (plants), "row_season" or "species"
    methods: tuple
    references: tuple = ("handheld",)
    first_case_only: bool = False
    workers: int = 2  # 1 where stage times are the result

    def cases(self) -> list:
        if self.setting == "plants":
            return plants.default_cases(quick=False)
        if self.setting == "season":
            return season.season_cases()
        if self.setting == "row_season":
            return season.row_season_cases()
        if self.setting == "species":
            return species.species_cases(species.helios_dataset())
        cases = rows.default_row_cases(quick=False, references=self.references)
        return cases[:1] if self.first_case_only else cases

    def run(self, cache_dir, progress: bool = True) -> pd.DataFrame:
        """The protocol's rows, computed (each (case, method) read from ``cache_dir`` when there)."""
        if self.setting == "plants":
            return plants.run_experiments(self.cases(), list(self.methods), cache_dir=cache_dir, workers=self.workers,
                                          progress=progress)
        if self.setting == "season":
            return season.run_season_experiments(self.cases(), self.methods, cache_dir=cache_dir, workers=self.workers,
                                                 progress=progress)
        if self.setting == "species":  # one row per case, nothing cached: about 15 min
            tables = run_cases(species.species_rows, self.cases(), (), 1, self.workers, progress=progress,
                               desc="species")
            return pd.concat(tables, ignore_index=True).sort_values(["instance", "view_space"], ignore_index=True)
        if self.setting == "row_season":
            return season.run_row_season_experiments(self.cases(), self.methods, make_config("row"), cache_dir=cache_dir,
                                                     workers=self.workers, progress=progress)
        return rows.run_row_experiments(self.cases(), list(self.methods), make_config("row"), cache_dir=cache_dir,
                                        workers=self.workers, progress=progress)

    def cached(self, cache_dir) -> pd.DataFrame | None:
        """The protocol's rows from ``cache_dir`` when every (case, method) is there, else None."""
        if self.setting == "plants":
            return plants.cached_experiments(self.cases(), list(self.methods), cache_dir=cache_dir)
        if self.setting == "species":
            return None
        if self.setting in ("season", "row_season"):
            experiment, setting = ((season.SEASON_EXPERIMENTS, "plant") if self.setting == "season"
                                   else (season.ROW_SEASON_EXPERIMENTS, "row"))
            return cached_experiments(experiment, self.cases(), list(self.methods), make_config(setting), cache_dir)
        return rows.cached_row_experiments(self.cases(), list(self.methods), make_config("row"), cache_dir=cache_dir)


_PLANT_METHODS = ("ours", "gmc", "one-shot-no-prior", "optimum", "ma-scvp", "ma-scvp-oracle")  # Table I
PROTOCOLS = {
    "table1": Protocol("plants", _PLANT_METHODS),
    "table2": Protocol("plants", ("ours",)),
    "tables3_4": Protocol("plants", tuple(ablation.ABLATION_METHODS)),
    "table1_learned": Protocol("plants", ("ours", "ours-pc-nbv", "ma-scvp", "ma-scvp-oracle")),
    "tables5_6": Protocol("rows", tuple(rows.ALL_METHODS), references=REFERENCES),
    "table7": Protocol("rows", ("pose-noise",)),
    "planning_time": Protocol("rows", ("ours", "blockwise-nbv"), first_case_only=True, workers=1),
    "season": Protocol("season", season.ARMS),
    "row_season": Protocol("row_season", season.ARMS),
    "species": Protocol("species", ("ours",)),  # on a Helios dataset: species.helios_dataset()
}


def protocol(name: str) -> Protocol:
    if name not in PROTOCOLS:
        raise ConfigError(f"no protocol named {name!r}; choose from {', '.join(PROTOCOLS)}")
    return PROTOCOLS[name]


def provenance() -> dict:
    """``provenance.json``: per protocol, the commit, command, date and machine that wrote its rows."""
    path = SHIPPED / PROVENANCE
    return json.loads(path.read_text()) if path.is_file() else {}


def shipped_rows(name: str) -> pd.DataFrame | None:
    """The shipped rows of protocol ``name`` (None when none are shipped)."""
    protocol(name)
    path = SHIPPED / f"{name}.parquet"
    return pd.read_parquet(path) if path.is_file() else None


def describe(name: str) -> str:
    """Where the shipped rows of protocol ``name`` come from, in words."""
    entry = provenance().get(name)
    if entry is None:
        return "shipped with tpvp"
    dirty = " plus uncommitted changes" if entry.get("dirty") else ""
    return (f"shipped with tpvp, written on {entry['date_utc'][:10]} at commit {entry['commit'][:7]}{dirty} by "
            f"`{entry['command']}` ({entry['machine']})")


def _git(*args) -> str:
    try:
        return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, timeout=30).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return ""


def refresh(names=tuple(PROTOCOLS), cache_dir=None, progress: bool = True) -> dict:
    """Recompute the shipped rows of the protocols ``names`` (their full cases and methods; the
    experiment cache ``cache_dir`` answers the tasks it holds) and write them with their
    provenance. Returns the new provenance."""
    cache_dir = Path(cache_dir or experiment_cache())
    for name in names:
        protocol(name)  # every name is checked before any work
    entries = provenance()
    # uncommitted changes to the code (the shipped rows themselves aside)
    commit, dirty = _git("rev-parse", "HEAD"), bool(_git("status", "--porcelain", "--", "tpvp", ":!tpvp/data/results"))
    for name in names:
        start = time.monotonic()
        table = PROTOCOLS[name].run(cache_dir / PROTOCOLS[name].setting, progress=progress)
        atomic_write_bytes(SHIPPED / f"{name}.parquet", table.to_parquet(index=False))
        entries[name] = {"commit": commit, "dirty": dirty, "command": f"python -m tpvp.experiments.shipped refresh {name}",
                         "date_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
                         "machine": f"{platform.machine()}, {_cores()} cores", "rows": len(table),
                         # the refresh's own time: tasks the experiment cache held are read, not computed
                         "refresh_minutes": round((time.monotonic() - start) / 60, 1)}
        atomic_write_text(SHIPPED / PROVENANCE, json.dumps(entries, indent=1, sort_keys=True) + "\n")
    return entries


def _cores() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tpvp.experiments.shipped", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command")
    again = sub.add_parser("refresh", help="recompute the shipped rows (the experiment cache answers what it holds)")
    again.add_argument("names", nargs="*", metavar="NAME", help=f"protocols (default: all: {', '.join(PROTOCOLS)})")
    again.add_argument("--cache", type=Path, default=None, help="the experiment cache (default: outputs/cache)")
    args = parser.parse_args(argv)

    def run(args) -> int:
        if args.command == "refresh":
            refresh(args.names or tuple(PROTOCOLS), args.cache)
        for name in PROTOCOLS:
            print(f"{name}: {describe(name)}" if (SHIPPED / f"{name}.parquet").is_file() else f"{name}: not shipped")
        return 0
    args.func = run
    return run_command(args, "python -m tpvp.experiments.shipped")


if __name__ == "__main__":
    sys.exit(main())
