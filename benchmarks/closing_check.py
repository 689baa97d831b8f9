"""The closing check of a one-shot plan (issue 50, item 3): what a session gains when, every planned
view captured, it re-plans from the captures and adds the views that close a gap
(:func:`tpvp.simulate.single_plant.run_case` with ``closing=True``; ``tpvp session plan`` at a
session's end does the same with the same captures).

Evaluation data, run once: generated seeds 0-2 and the bundled real pair (the 42-case protocol per
view space), each planned for 98 % with the default (constant) rule, one-shot and with the closing
check, ideal sensor. The exact optimum for 98 % of each case is read from
``results/miss_model_evaluate.csv`` (the same cases). Printed per view space and plan: views per
optimum, true coverage (mean, lowest, cases below 97 % and 96 %); per view space the cases below
98 % one-shot, the cases whose views the check changed (below 98 % or not) and what it gained there.

Usage:
    python benchmarks/closing_check.py [--workers 2] [--summarise]
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

import pandas as pd

from tpvp.config_loading import make_config
from tpvp.experiments import plants
from tpvp.io import atomic_write_text
from tpvp.parallel import run_cases
from tpvp.setcover.miss_model import plan_summary
from results_file import write_results

RESULTS = Path(__file__).resolve().parent / "results"
ASKED = 0.98
KEYS = ["instance", "view_space", "rotation_deg", "initial_view"]


def case_rows(case) -> list:
    """One case's plan for 98 %, one-shot and with the closing check (they share the warm-up, the
    registration and the one-shot plan)."""
    from tpvp.pipeline.jit import compile_kernels
    from tpvp.simulate.single_plant import build_scene, run_case, transfer

    compile_kernels()
    config = case.config(make_config("plant"))
    config = replace(config, selection=replace(config.selection, coverage_target=ASKED))
    scene = build_scene(*case.instance.load(), config)
    shared = transfer(scene, config)
    rows = []
    for closing in (False, True):
        result = run_case(scene, config, transferred=shared, closing=closing)
        rows.append({**case.labels(), "plan": "closing check" if closing else "one-shot", "views": result.n_views,
                     "coverage": result.coverage, "checks": len(result.replans),
                     "views_added": sum(step.views_added for step in result.replans),
                     "views_dropped": sum(step.views_dropped for step in result.replans)})
    return [pd.DataFrame(rows)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--results", type=Path, default=RESULTS)
    parser.add_argument("--summarise", action="store_true",
                        help="only summarise the rows of results/closing_check.csv again (no case is run)")
    args = parser.parse_args()
    started = time.perf_counter()
    cases = plants.default_cases()  # the generated seeds' 72 cases and the bundled pair's 12
    if args.summarise:
        rows = pd.read_csv(args.results / "closing_check.csv")
        made = (args.results / "closing_check.md").read_text().splitlines()[2]
        run = made.split(" (", 1)[1].rsplit(").", 1)[0].removesuffix(", summarised again") + ", summarised again"
    else:
        rows = pd.concat(run_cases(case_rows, cases, (), 1, args.workers, desc="cases"), ignore_index=True)
        optimum = pd.read_csv(args.results / "miss_model_evaluate.csv").drop_duplicates(KEYS)[KEYS + ["optimum_views"]]
        rows = rows.merge(optimum, on=KEYS, how="left", validate="many_to_one")
        if rows["optimum_views"].isna().any():
            raise SystemExit("results/miss_model_evaluate.csv lacks the optimum of some case: run miss_model.py "
                             "--mode evaluate")
        atomic_write_text(args.results / "closing_check.csv", rows.to_csv(index=False))
        run = (f"{len(cases)} cases (generated seeds {list(plants.GENERATED_SEEDS)} and the bundled pair), "
               f"{time.perf_counter() - started:.0f} s on {args.workers} workers")
    summary = plan_summary(rows, by=("view_space", "plan"))
    one_shot, closing = (rows[rows["plan"] == plan].set_index(KEYS) for plan in ("one-shot", "closing check"))
    changed = (closing["views_added"] + closing["views_dropped"]) > 0
    below = one_shot["coverage"] < ASKED
    gain = 100 * (closing["coverage"] - one_shot["coverage"])[changed]
    space = one_shot.index.get_level_values("view_space")
    per_space = pd.DataFrame({"one_shot_below_98": below.groupby(space).sum(),
                              "changed": changed.groupby(space).sum(),
                              "changed_below_98": (changed & below).groupby(space).sum(),
                              "changed_at_98_or_more": (changed & ~below).groupby(space).sum(),
                              "views_added": closing["views_added"].groupby(space).sum(),
                              "coverage_gain_changed": gain.groupby(space[changed.to_numpy()]).mean(),
                              "closing_below_98": (closing["coverage"] < ASKED).groupby(space).sum()}).reset_index()
    for column in ("coverage_mean", "coverage_min", "below_97", "below_96"):
        summary[column] = 100 * summary[column]
    write_results(args.results / "closing_check.md",
                  [("plans for 98 % (coverage and shares in %)", summary),
                   ("cases below 98 % and cases whose views the check changed (coverage gain in points)", per_space)],
                  run)


if __name__ == "__main__":
    main()
