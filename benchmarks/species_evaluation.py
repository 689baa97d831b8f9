"""Table II across species (issue 39): the calibrated coverage-target rule and per-organ targets on
plants of an independent generator (Helios), beside tomato and maize of our generator and the
bundled real pair (:func:`tpvp.experiments.species.species_rows` per case: the plan for 0.98 beside
the exact optimum, true coverage per organ; on a fruiting plant fruit=1.0,leaf=0.95 against the full
cover). The same rows ship as the ``species`` protocol (``python -m tpvp.experiments.shipped
refresh species``, notebook 03).

Usage:
    python -m data_tools helios --species ... --ages ... --plants 3 --output data/helios
    python benchmarks/species_evaluation.py --dataset data/helios [--workers 2]
    python benchmarks/species_evaluation.py --rows benchmarks/results/species_evaluation.csv
Writes benchmarks/results/species_evaluation.md (and the rows with --output CSV).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import pandas as pd

from results_file import write_results
from tpvp.experiments import species
from tpvp.parallel import run_cases

RESULTS = Path(__file__).resolve().parent / "results" / "species_evaluation.md"
TITLES = {"overall": f"The evaluation species (Helios), at --coverage-target {species.SPECIES_TARGET}",
          "calibration_species": f"Helios {' and '.join(species.CALIBRATION_SPECIES)} (calibration species) alike",
          "per_species": "Per species and view space (organs: true coverage per organ)",
          "organ_targets": f"Organ targets {species.ORGAN_TARGETS} against --coverage-target 1.0 (cases with fruit)"}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dataset", type=Path, default=None, help="a dataset written by python -m data_tools helios")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--output", type=Path, default=None, help="CSV of every case's row")
    parser.add_argument("--rows", type=Path, default=None, metavar="CSV",
                        help="summarise the rows of an earlier run (an --output file) instead of running")
    args = parser.parse_args()
    started = time.perf_counter()
    if args.rows:
        raw = pd.read_csv(args.rows)
        what = f"{len(raw)} cases read from {args.rows}"
    else:
        cases = species.species_cases(args.dataset)
        raw = pd.concat(run_cases(species.species_rows, cases, (), 1, args.workers, desc="species"), ignore_index=True)
        what = f"{len(cases)} cases, {time.perf_counter() - started:.0f} s on {args.workers} workers"
    if args.output:
        raw.to_csv(args.output, index=False)
    tables = species.species_tables(raw)
    for name, table in tables.items():
        print(f"\n{TITLES[name]}\n{table.to_string(index=False)}")
    write_results(RESULTS, [(TITLES[name], table) for name, table in tables.items()], what)


if __name__ == "__main__":
    main()
