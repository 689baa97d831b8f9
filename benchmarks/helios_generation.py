"""Helios-grown plants measured (issue 39): 8 species x 3 plants x 4 sessions grown with
``python -m data_tools helios``'s library call at the default density, timed per species, and the
organs each session holds.

Each species is grown through ages where it has leaves and, for the fruiting ones, flowers or fruit
(Helios' phenology: tomato flowers from about 60 days, soybean and bean from 56, cowpea from 56-60
and fruits from 72, maize's tassel and ear from 48, rice's panicle from 60; strawberry flowers from
about 40 and fruits from 56-68; sugar beet is grown for its leaves and stays vegetative in its first
season). A plant's course depends on the age it is built at: of the three tomatoes built at 63 days,
the second flowers only from 69. One dataset per species, so each is timed on its own; the total is
their sum.

Usage:
    python benchmarks/helios_generation.py [--species S ...] [--plants 3] [--work DIR]
Writes benchmarks/results/helios_generation.md (with this command) and prints the tables.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from data_tools.helios import HeliosConfig, prepare_helios
from results_file import write_results
from tpvp.io import read_point_cloud
from tpvp.scene.organs import CODE, ORGANS

RESULTS = Path(__file__).resolve().parent / "results" / "helios_generation.md"
#: species -> session ages (days): leaves in every session, and flowers or fruit where the species bears them
SCHEDULE = {
    "tomato": (63, 66, 69, 72),
    "strawberry": (56, 60, 64, 68),
    "soybean": (56, 60, 64, 68),
    "bean": (56, 60, 64, 68),
    "cowpea": (72, 76, 80, 84),
    "maize": (50, 53, 56, 59),
    "rice": (60, 63, 66, 69),
    "sugarbeet": (30, 33, 36, 39),
}


def _size_mb(folder: Path) -> float:
    return sum(p.stat().st_size for p in folder.rglob("*") if p.is_file()) / 1e6


def _organ_rows(species: str, folder: Path, manifest: pd.DataFrame) -> list[dict]:
    """Per session age: the plants holding each organ, and its mean share of the points."""
    rows = []
    manifest = manifest.assign(age=(pd.to_datetime(manifest.date) - pd.Timestamp("2025-01-01")).dt.days)
    for age, sessions in manifest.groupby("age"):
        counts = np.array([np.bincount(read_point_cloud(folder / f, units="m", return_labels=True)[1],
                                       minlength=len(ORGANS)) for f in sessions.file])
        row = {"species": species, "age_days": int(age), "points_mean": int(counts.sum(axis=1).mean())}
        for organ in ORGANS[1:]:
            present = int((counts[:, CODE[organ]] > 0).sum())
            share = 100 * (counts[:, CODE[organ]] / counts.sum(axis=1)).mean()
            row[organ] = f"{present}/{len(counts)} ({share:.2g} %)" if present else "-"
        rows.append(row)
    return rows


def run(species: list[str], plants: int, work: Path):
    config = HeliosConfig(plants=plants)
    timing, organs = [], []
    for name in species:
        folder = work / name
        start = time.perf_counter()
        manifest = prepare_helios(folder, [name], SCHEDULE[name], config, progress=False)
        seconds = time.perf_counter() - start
        timing.append({"species": name, "ages_days": " ".join(map(str, SCHEDULE[name])), "plants": plants,
                       "sessions": len(manifest), "seconds": seconds, "s_per_session": seconds / len(manifest),
                       "points_min": int(manifest.points.min()), "points_max": int(manifest.points.max()),
                       "height_m_max": float(manifest.extent_z.max()), "MB_written": _size_mb(folder)})
        print(f"{name}: {seconds:.1f} s, {manifest.points.min():,}-{manifest.points.max():,} points", flush=True)
        organs += _organ_rows(name, folder, manifest)
    timing = pd.DataFrame(timing)
    total = pd.DataFrame([{"species": len(species), "plants": len(species) * plants,
                           "sessions": int(timing.sessions.sum()), "seconds": float(timing.seconds.sum()),
                           "points": int(sum((timing.points_min + timing.points_max) / 2 * timing.sessions)),
                           "GB_written": float(timing.MB_written.sum() / 1000)}])
    total = total.rename(columns={"points": "points (about)"})
    spacing = 1000 * config.spacing
    return [(f"Per species ({plants} plants x 4 sessions, {spacing:g} mm spacing)", timing),
            ("Total", total),
            ("Organs per session age: plants holding it, its mean share of the points", pd.DataFrame(organs))]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--species", nargs="+", default=list(SCHEDULE), choices=list(SCHEDULE))
    parser.add_argument("--plants", type=int, default=3)
    parser.add_argument("--work", type=Path, default=None, help="folder for the datasets (default: a temporary one)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as temporary:
        tables = run(args.species, args.plants, args.work or Path(temporary))
    for title, table in tables:
        print(f"\n{title}\n{table.to_string(index=False)}")
    write_results(RESULTS, tables, f"{len(args.species)} species x {args.plants} plants x 4 sessions, "
                                   f"one process on {os.cpu_count()} cores")
    print(json.dumps({"results": str(RESULTS)}))


if __name__ == "__main__":
    main()
