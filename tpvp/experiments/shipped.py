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
import math
import os
import platform
import sys
import time
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pandas as pd

from tpvp.config_loading import make_config
from tpvp.errors import ConfigError, run_command
from tpvp.experiments import ablation, plants, rows, season, species
from tpvp.experiments.runner import cached_experiments, experiment_cache
from tpvp.io import atomic_write_bytes, atomic_write_text
from tpvp.parallel import run_cases
from tpvp.provenance import code_digest, tree_state
from tpvp.simulate import row_cases

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
        cases = row_cases.default_row_cases(quick=False, references=self.references)
        return cases[:1] if self.first_case_only else cases

    def run(self, cache_dir, progress: bool = True, cases=None, methods=None, workers=None) -> pd.DataFrame:
        """The protocol's rows, computed (each (case, method) read from ``cache_dir`` when there);
        ``cases`` and ``methods``: only these of the protocol's (:func:`verify`)."""
        cases = self.cases() if cases is None else list(cases)
        methods = list(self.methods if methods is None else methods)
        workers = self.workers if workers is None else workers
        if self.setting == "plants":
            return plants.run_experiments(cases, methods, cache_dir=cache_dir, workers=workers, progress=progress)
        if self.setting == "season":
            return season.run_season_experiments(cases, methods, cache_dir=cache_dir, workers=workers,
                                                 progress=progress)
        if self.setting == "species":  # one row per case, nothing cached: about 15 min
            tables = run_cases(species.species_rows, cases, (), 1, workers, progress=progress, desc="species")
            return pd.concat(tables, ignore_index=True).sort_values(["instance", "view_space"], ignore_index=True)
        if self.setting == "row_season":
            return season.run_row_season_experiments(cases, methods, make_config("row"), cache_dir=cache_dir,
                                                     workers=workers, progress=progress)
        return rows.run_row_experiments(cases, methods, make_config("row"), cache_dir=cache_dir, workers=workers,
                                        progress=progress)

    def tasks(self) -> list[tuple]:
        """Every ``(case, method)`` of the protocol (the species protocol: one task per case)."""
        methods = self.methods[:1] if self.setting == "species" else self.methods
        return [(case, method) for case in self.cases() for method in methods]

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
    """Where the shipped rows of protocol ``name`` come from, in words; rows computed by code other
    than this checkout's (:func:`tpvp.provenance.code_digest`) are said to be stale."""
    entry = provenance().get(name)
    if entry is None:
        return "shipped with tpvp"
    text = (f"shipped with tpvp, written on {entry['date_utc'][:10]} at commit {entry['commit'][:7]} by "
            f"`{entry['command']}` ({entry['machine']})")
    if not entry.get("clean", not entry.get("dirty", True)) or entry.get("digest") != code_digest():
        text += (f"; STALE: {_not_this_code(entry)}, so they may differ from what this code computes "
                 f"(`python -m tpvp.experiments.shipped verify {name}` recomputes a sample and compares)")
    return text


def _not_this_code(entry: dict) -> str:
    if not entry.get("clean", not entry.get("dirty", True)):
        return "computed from a tree with changes beyond that commit, code no commit holds"
    if "digest" not in entry:
        return "written before rows recorded the digest of their code"
    return "computed by code that differs from this checkout's"


def refresh(names=tuple(PROTOCOLS), cache_dir=None, progress: bool = True) -> dict:
    """Recompute the shipped rows of the protocols ``names`` (their full cases and methods; the
    experiment cache ``cache_dir`` answers the tasks it holds: its keys hold the code's digest)
    and write them with their provenance: the commit, the code's digest, the command and the
    machine. Only from a clean tree, so the commit names the code. Returns the new provenance."""
    cache_dir = Path(cache_dir or experiment_cache())
    for name in names:
        protocol(name)  # every name is checked before any work
    commit, clean = tree_state(ROOT)
    if commit is None or not clean:
        raise ConfigError("refresh the shipped rows from a clean tree (commit the code first: `git status -- tpvp "
                          "data_tools` lists changes), so that their provenance names the commit that computed them")
    entries = provenance()
    for name in names:
        start = time.monotonic()
        table = PROTOCOLS[name].run(cache_dir / PROTOCOLS[name].setting, progress=progress)
        atomic_write_bytes(SHIPPED / f"{name}.parquet", table.to_parquet(index=False))
        entries[name] = {"commit": commit, "clean": True, "digest": code_digest(),
                         "command": f"python -m tpvp.experiments.shipped refresh {name}",
                         "date_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
                         "machine": f"{platform.machine()}, {_cores()} cores", "rows": len(table),
                         # the refresh's own time: tasks the experiment cache held are read, not computed
                         "refresh_minutes": round((time.monotonic() - start) / 60, 1)}
        atomic_write_text(SHIPPED / PROVENANCE, json.dumps(entries, indent=1, sort_keys=True) + "\n")
    return entries


def _measured(table: pd.DataFrame) -> list[str]:
    """The columns a recomputation must reproduce: all but run times and cache states."""
    return [c for c in table.columns if not c.startswith("seconds") and c not in ("oracle_cached", "refresh_minutes")]


def _same(a, b) -> bool:
    """Equal cells: NaN equals NaN; a list equals the array Parquet reads it back as."""
    if isinstance(a, (list, tuple, np.ndarray)) or isinstance(b, (list, tuple, np.ndarray)):
        return np.array_equal(np.asarray(a), np.asarray(b), equal_nan=np.asarray(a).dtype.kind == "f")
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return bool(a == b)


def _task_seconds(shipped: pd.DataFrame) -> pd.Series:
    """Per method, the longest its shipped task took, the case's oracle included (rows)."""
    took = shipped["seconds_task"] + shipped.get("seconds_oracle", 0)
    return took.groupby(shipped["method"]).max()


def verify(names=tuple(PROTOCOLS), sample: int = 3, seed: int = 0, max_task_seconds: float | None = None,
           progress: bool = True) -> list[dict]:
    """Recompute a seeded sample of ``sample`` tasks of each protocol at this checkout, nothing
    cached, and compare every row with the shipped rows, run times and cache states aside: a row
    reproduces when a shipped row equals it in every other column. ``max_task_seconds``: sample
    only tasks whose shipped rows took at most this long (the suite's quick check). One report per
    task: ``protocol``, ``case``, ``method``, ``rows``, ``reproduced`` and the differing columns."""
    import random

    reports = []
    for name in names:
        spec, shipped = protocol(name), shipped_rows(name)
        if shipped is None:
            raise ConfigError(f"{name}: no shipped rows to verify")
        try:
            tasks = spec.tasks()
        except ConfigError as exc:  # the species protocol's Helios dataset is grown, not shipped
            print(f"{name}: not verified: {exc}", flush=True)
            reports.append({"protocol": name, "case": None, "method": None, "rows": 0, "reproduced": None,
                            "differing": [], "why": str(exc)})
            continue
        if max_task_seconds is not None and "seconds_task" in shipped.columns:
            took = _task_seconds(shipped)
            tasks = [(c, m) for c, m in tasks if took.get(m, math.inf) <= max_task_seconds]
        elif max_task_seconds is not None:
            tasks = []  # run times not recorded: nothing known to be quick
        for case, method in random.Random(f"{seed}:{name}").sample(tasks, min(sample, len(tasks))):
            again = spec.run(None, progress=False, cases=[case], methods=[method], workers=1)
            columns = [c for c in _measured(again) if c in shipped.columns]
            missing = [c for c in _measured(again) if c not in shipped.columns]
            table = shipped[columns].to_dict("records")
            differing: set = set(missing)
            reproduced = not missing
            for row in again[columns].to_dict("records"):
                nearest = max(table, key=lambda other: sum(_same(row[c], other[c]) for c in columns))
                off = [c for c in columns if not _same(row[c], nearest[c])]
                differing |= set(off)
                reproduced &= not off
            reports.append({"protocol": name, "case": " ".join(f"{k}={v}" for k, v in case.labels().items()),
                            "method": method, "rows": len(again), "reproduced": reproduced,
                            "differing": sorted(differing)})
            if progress:
                verdict = "reproduced" if reproduced else f"DIFFERS in {', '.join(sorted(differing))}"
                print(f"{name}: {reports[-1]['case']} {method}: {len(again)} row(s) {verdict}", flush=True)
    return reports


def _cores() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tpvp.experiments.shipped", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command")
    again = sub.add_parser("refresh", help="recompute the shipped rows (the experiment cache answers what it holds); "
                                           "only from a clean tree")
    again.add_argument("names", nargs="*", metavar="NAME", help=f"protocols (default: all: {', '.join(PROTOCOLS)})")
    again.add_argument("--cache", type=Path, default=None, help="the experiment cache (default: outputs/cache)")
    check = sub.add_parser("verify", help="recompute a seeded sample of each protocol's tasks here, nothing cached, and "
                                          "compare them with the shipped rows (run times aside); exit 1 if any differs")
    check.add_argument("names", nargs="*", metavar="NAME", help="protocols (default: all)")
    check.add_argument("--sample", type=int, default=3, help="tasks per protocol (default: %(default)s)")
    check.add_argument("--seed", type=int, default=0, help="the sample's seed (default: %(default)s)")
    check.add_argument("--max-task-seconds", type=float, default=None, metavar="S",
                       help="sample only tasks whose shipped rows took at most S seconds (default: any)")
    args = parser.parse_args(argv)

    def run(args) -> int:
        if args.command == "verify":
            if args.sample < 1:
                raise ConfigError(f"--sample must be at least 1, got {args.sample}")
            reports = verify(args.names or tuple(PROTOCOLS), args.sample, args.seed, args.max_task_seconds)
            failed = [r for r in reports if r["reproduced"] is False]
            skipped = [r["protocol"] for r in reports if r["reproduced"] is None]
            ran = len(reports) - len(skipped)
            print(f"{ran - len(failed)} of {ran} sampled tasks reproduce the shipped rows (code {code_digest()[:12]})"
                  + (f"; not verified: {', '.join(skipped)}" if skipped else ""))
            return 1 if failed else 0
        if args.command == "refresh":
            refresh(args.names or tuple(PROTOCOLS), args.cache)
        for name in PROTOCOLS:
            print(f"{name}: {describe(name)}" if (SHIPPED / f"{name}.parquet").is_file() else f"{name}: not shipped")
        return 0
    args.func = run
    return run_command(args, "python -m tpvp.experiments.shipped")


if __name__ == "__main__":
    sys.exit(main())
