"""Calibration for the species evaluation (issue 39), on tomato and maize only: the coverage-target
rule (the planning surface's share a 98 % request asks for) and the organ margin of per-organ
targets, on Helios tomato and maize grown from other seeds than the evaluation's and on our
generated tomato and maize of seeds 10-12 (never the evaluation seeds 0-2).

Per case (each pair of the Helios calibration dataset, rotation 0, initial view 17; each generated
pair, rotation 0, initial views 17 / 8 / 21; both view spaces): the warm-up, the registration and
the planning surface once; then the selection for every planning target of --targets on the
planning surface as it is (``planning_miss_ratio = 1``), its views and true coverage beside the
exact optimum for 98 % (perfect knowledge, same initial view); what the planner knows of its own
prediction (``fit``: the registration's Chamfer to the coarse scan over the plant's size,
``unexplained``: the coarse scan's share farther than a planning voxel from the aligned previous
session, the planning surface's share the warm-up saw and its voxel classes); and on a plant whose
previous session holds fruit, ``fruit=1.0,leaf=0.95`` with every organ margin of --margins: views
and true fruit coverage.

Printed: per source and view space, the smallest planning target whose mean true coverage reaches
98 % + MARGIN with no case below 97 % + MARGIN (and with the issue's own 98 % / 97 %), as a miss
ratio (1 - planning) / (1 - 0.98), and its views per optimum; per source and view space and organ
margin, the true fruit coverage (mean, lowest, cases at 99.5 % or more) and views, and the chosen
margin: the most cases at 99.5 % over both view spaces, then the higher fruit mean, then fewer
views. Every row goes to --output; --rows summarises such files instead of running. Every row and
table records its split (``calibration``: the Helios evaluation dataset holds pairs of the same names)
and the seed its plants come from (``seed``: a generated pair's seed, the Helios dataset's --helios-seed;
rows of earlier files without the columns get them, no measured value changes).

Usage:
    python -m data_tools helios --species tomato maize --ages ... --plants 3 --seed 1 --output DIR
    python benchmarks/species_calibration.py --dataset DIR [--output rows.csv]
    python benchmarks/species_calibration.py --rows rows.csv [more.csv ...]
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from tpvp.config_loading import make_config
from tpvp.experiments import plants
from tpvp.experiments.species import HELIOS_SEEDS, seeds_of, with_split
from tpvp.parallel import run_cases
from coverage_target_calibration import selection_on_prediction
from results_file import write_results

RESULTS = Path(__file__).resolve().parent / "results"
ASKED = 0.98
MARGIN = 0.001  # as benchmarks/coverage_target_calibration.py: room for the seed-to-seed spread
# Planning targets of the miss ratios 1, 0.75, 0.5, 0.375 and 0.25 (the sphere's rule so far).
TARGETS = (0.98, 0.985, 0.99, 0.9925, 0.995)
MARGINS = (0, 1, 2, 3, 4)
ORGAN_TARGETS = "fruit=1.0,leaf=0.95"
FRUIT_ASKED = 0.995  # the target for the true fruit coverage
CALIBRATION_SPECIES = ("tomato", "maize")
GENERATED_SEEDS = (10, 11, 12)
SPLIT = "calibration"


def calibration_cases(dataset, seeds=GENERATED_SEEDS) -> list:
    """Tomato and maize only: every pair of the Helios calibration dataset and the generated seeds."""
    cases = []
    if dataset is not None:
        table = plants.dataset_table(dataset)
        rows = table.index[table["species"].str.lower().isin(CALIBRATION_SPECIES)].tolist()
        cases += plants.case_list(plants.dataset_instances(dataset, pairs=rows), rotations=(0.0,), initial_views=(17,))
    if seeds:
        cases += plants.case_list(plants.generated_instances(seeds=tuple(seeds)), rotations=(0.0,))
    return cases


def calibration_rows(case, targets=TARGETS, margins=MARGINS) -> list:
    """One case's rows (a task of :func:`tpvp.parallel.run_cases`): one per planning target, one per
    organ margin on a plant with fruit."""
    from tpvp.simulate.optimum import optimum
    from tpvp.simulate.single_plant import build_scene, known, run_case, transfer
    from tpvp.pipeline.jit import compile_kernels
    from tpvp.pipeline.plan import planning_surface
    from tpvp.scene.organs import CODE
    from tpvp.setcover.miss_model import planning_features

    compile_kernels()
    config = case.config(make_config("plant"))
    scene = build_scene(*case.instance.load(), config, organs=case.instance.organs())
    shared = transfer(scene, config)
    surface = planning_surface(known(scene), config, shared)
    labels = {**case.labels(), **planning_features(config, shared, surface),
              "optimum_views": int(optimum(scene, config, targets=(ASKED,))["views"].iloc[0])}
    rows = []
    for target in targets:
        views, coverage, _ = selection_on_prediction(scene, config, shared, surface, target)
        rows.append({**labels, "kind": "target", "target": target, "views": views, "coverage": coverage})
    if scene.previous_organs is not None and (scene.previous_organs == CODE["fruit"]).any():
        for margin in margins:
            organ = replace(config, selection=replace(config.selection, organ_targets=ORGAN_TARGETS,
                                                      organ_margin_voxels=margin))
            result = run_case(scene, organ, transferred=shared)
            rows.append({**labels, "kind": "organ", "margin": margin, "views": result.n_views,
                         "coverage": result.coverage, "fruit": result.organ_coverage.get("fruit"),
                         "leaf": result.organ_coverage.get("leaf")})
    return [pd.DataFrame(rows)]


def _group(raw: pd.DataFrame) -> np.ndarray:
    return np.where(raw["source"] == "dataset", "helios", "generated")


def _labels(raw: pd.DataFrame) -> pd.DataFrame:
    """``raw`` with its split and seed columns (:func:`tpvp.experiments.species.with_split`)."""
    return with_split(raw, SPLIT, HELIOS_SEEDS[SPLIT]) if not {"split", "seed"} <= set(raw.columns) else raw


def _splits(values) -> str:
    return ",".join(sorted(set(values)))


def _labels_first(table: pd.DataFrame) -> pd.DataFrame:
    return table[["split", "seed", *[c for c in table.columns if c not in ("split", "seed")]]]


def rule_table(raw: pd.DataFrame, asked=ASKED, margin=MARGIN) -> pd.DataFrame:
    """Per group (helios, generated, both) and view space: the smallest passing planning target."""
    rows = _labels(raw)
    rows = rows[rows["kind"] == "target"].assign(ratio=lambda r: r["views"] / r["optimum_views"], group=_group)
    rows = pd.concat([rows, rows.assign(group="both")], ignore_index=True)
    out = []
    for (group, space), cases in rows.groupby(["group", "view_space"], sort=False):
        summary = cases.groupby("target").agg(coverage_mean=("coverage", "mean"), coverage_min=("coverage", "min"),
                                              views_per_optimum=("ratio", "mean"), cases=("views", "size"))
        ok = summary[(summary["coverage_mean"] >= asked + margin) & (summary["coverage_min"] >= asked - 0.01 + margin)]
        target = ok.index.min() if len(ok) else np.nan
        picked = summary.loc[target] if len(ok) else pd.Series(dtype=float)
        out.append({"split": _splits(cases["split"]), "seed": seeds_of(cases["seed"]),
                    "group": group, "view_space": space, "cases": int(summary["cases"].iloc[0]),
                    "planning_target": target, "miss_ratio": (1 - target) / (1 - asked),
                    **{k: picked.get(k, np.nan) for k in ("views_per_optimum", "coverage_mean", "coverage_min")}})
    return pd.DataFrame(out)


def target_table(raw: pd.DataFrame) -> pd.DataFrame:
    """Per group, view space and planning target: views per optimum and true coverage."""
    rows = _labels(raw)
    rows = rows[rows["kind"] == "target"].assign(ratio=lambda r: r["views"] / r["optimum_views"], group=_group)
    return rows.groupby(["group", "view_space", "target"]).agg(
        split=("split", _splits), seed=("seed", seeds_of),
        cases=("views", "size"), views_per_optimum=("ratio", "mean"), coverage_mean=("coverage", "mean"),
        coverage_min=("coverage", "min")).reset_index().pipe(_labels_first)


def margin_table(raw: pd.DataFrame) -> pd.DataFrame:
    """Per group, view space and organ margin: views and true fruit coverage."""
    if "margin" not in raw:
        return pd.DataFrame()
    rows = _labels(raw)
    rows = rows[rows["kind"] == "organ"].assign(group=_group, reached=lambda r: r["fruit"] >= FRUIT_ASKED)
    return rows.groupby(["group", "view_space", "margin"]).agg(
        split=("split", _splits), seed=("seed", seeds_of),
        cases=("views", "size"), views=("views", "mean"), fruit_mean=("fruit", "mean"), fruit_min=("fruit", "min"),
        cases_at_995=("reached", "sum"), leaf_mean=("leaf", "mean"), coverage=("coverage", "mean")).reset_index(
    ).pipe(_labels_first)


def chosen_margin(margins: pd.DataFrame) -> pd.DataFrame:
    """The margin with the most cases at :data:`FRUIT_ASKED` over both view spaces, then the higher
    fruit mean, then fewer views."""
    if margins.empty:
        return margins
    score = margins.groupby("margin").agg(cases_at_995=("cases_at_995", "sum"), fruit_mean=("fruit_mean", "mean"),
                                          views=("views", "mean")).reset_index()
    return score.sort_values(["cases_at_995", "fruit_mean", "views"], ascending=[False, False, True],
                             kind="stable").head(1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dataset", type=Path, default=None, help="the Helios calibration dataset (tomato, maize)")
    parser.add_argument("--seeds", nargs="*", type=int, default=list(GENERATED_SEEDS), help="generated seeds")
    parser.add_argument("--helios-seed", type=int, default=HELIOS_SEEDS[SPLIT],
                        help="the seed --dataset was grown from (python -m data_tools helios --seed; default: "
                             "%(default)s); recorded in the rows' seed column")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--output", default=None, help="CSV of every row")
    parser.add_argument("--rows", nargs="+", default=None, metavar="CSV",
                        help="summarise the rows of earlier runs (--output files) instead of running")
    parser.add_argument("--results", default=str(RESULTS), metavar="DIR")
    args = parser.parse_args()
    started = time.perf_counter()
    if args.rows:
        raw = pd.concat([pd.read_csv(path) for path in args.rows], ignore_index=True)
        raw = with_split(raw, SPLIT, args.helios_seed) if "seed" not in raw else raw
        what = f"{raw['instance'].nunique()} pairs, {len(raw)} rows read from {', '.join(args.rows)}"
    else:
        cases = calibration_cases(args.dataset, args.seeds)
        raw = pd.concat(run_cases(calibration_rows, cases, (), 1, args.workers, desc="calibration"),
                        ignore_index=True)
        raw = with_split(raw, SPLIT, args.helios_seed)
        what = (f"{len(cases)} cases (tomato and maize: the Helios dataset {args.dataset}, generated seeds "
                f"{args.seeds}), {time.perf_counter() - started:.0f} s on {args.workers} workers")
    if args.output:
        raw.to_csv(args.output, index=False)
    margins = margin_table(raw)
    tables = [("smallest planning target with mean >= 98.1 % and no case below 97.1 %", rule_table(raw)),
              ("smallest planning target with the issue's mean >= 98 % and no case below 97 %",
               rule_table(raw, margin=0)),
              ("per planning target", target_table(raw)),
              (f"{ORGAN_TARGETS} per organ margin (planning voxels)", margins),
              ("chosen organ margin", chosen_margin(margins))]
    pd.set_option("display.width", 200)
    for title, table in tables:
        print(f"\n{title}:\n{table.round(4).to_string(index=False)}")
    write_results(Path(args.results) / "species_calibration.md", tables, what)


if __name__ == "__main__":
    main()
