"""Re-planning from the captures (``selection.replan_after``): calibration and evaluation.

``--mode calibrate`` (seeds 10, 11, 12, never the evaluation seeds): each case's warm-up and
registration are shared by every miss ratio r of --ratios; the plan for a 98 % request sees
``1 - r x 0.02`` of the predicted planning surface and is re-planned after every --replan-after
views until no view is left. Printed per view space and r: views, views / the exact optimum for
98 % (perfect knowledge, same initial view), true coverage (mean, min); and per view space the
largest r whose mean reaches 98 % + MARGIN with no case below 97 % + MARGIN (the rule of
``benchmarks/coverage_target_calibration.py``): :data:`tpvp.setcover.config.CALIBRATED_REPLAN_MISS_RATIO`.

``--mode evaluate`` (seeds 0, 1, 2 and the bundled real pair): for each target of --targets, the
one-shot plan (the calibrated one-shot rule) and the re-planned plan (the calibrated re-planning
rule) beside the exact optimum; views, their ratio to the optimum, true coverage, the path's
ratio to the one-shot plan's and the re-planning time.

Both use the 36-case protocol per view space (rotations 0 and 45, initial views 17 / 8 / 21) and
run cases on --workers processes.

Usage:
    python benchmarks/replanning.py --mode calibrate [--ratios 0.5 0.75 1.0]
    python benchmarks/replanning.py --mode evaluate [--targets 0.95 0.98 0.99]
"""

from __future__ import annotations

import argparse
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import pandas as pd

from tpvp.config_loading import make_config, with_overrides
from tpvp.setcover.config import CALIBRATED_MISS_RATIO, CALIBRATED_REPLAN_MISS_RATIO
from tpvp.experiments import plants
from results_file import write_results

RESULTS = Path(__file__).resolve().parent / "results"
RATIOS = (0.25, 0.5, 0.75, 1.0)
TARGETS = (0.95, 0.98, 0.99)
ASKED = 0.98
MARGIN = 0.001  # as benchmarks/coverage_target_calibration.py


def _case_scene(case, overrides):
    from tpvp.simulate.single_plant import build_scene, transfer
    from tpvp.pipeline.jit import compile_kernels

    compile_kernels()
    config = case.config(make_config("plant", overrides))
    scene = build_scene(*case.instance.load(), config)
    return config, scene, transfer(scene, config)


def _calibrate_case(case, ratios, replan_after) -> list[dict]:
    from tpvp.simulate.optimum import optimum
    from tpvp.simulate.single_plant import run_case

    config, scene, shared = _case_scene(case, {"selection.coverage_target": ASKED,
                                               "selection.replan_after": replan_after})
    best = int(optimum(scene, config, targets=(ASKED,))["views"].iloc[0])
    rows = []
    for ratio in ratios:
        result = run_case(scene, with_overrides(config, {"selection.planning_miss_ratio": ratio}), transferred=shared)
        rows.append({**case.labels(), "ratio": ratio, "views": result.n_views, "optimum_views": best,
                     "coverage": result.coverage, "replans": len(result.replans),
                     "views_added": sum(r.views_added for r in result.replans),
                     "views_dropped": sum(r.views_dropped for r in result.replans)})
    return rows


def _evaluate_case(case, targets, replan_after) -> list[dict]:
    from tpvp.simulate.optimum import optimum
    from tpvp.simulate.single_plant import run_case

    config, scene, shared = _case_scene(case, {})
    best = optimum(scene, config, targets=targets).set_index("target")
    rows = []
    for target in targets:
        asked = with_overrides(config, {"selection.coverage_target": target})
        one_shot = run_case(scene, asked, transferred=shared)
        replanned = run_case(scene, with_overrides(asked, {"selection.replan_after": replan_after}), transferred=shared)
        rows.append({**case.labels(), "target": target, "optimum_views": int(best.loc[target, "views"]),
                     "one_shot_views": one_shot.n_views, "one_shot_coverage": one_shot.coverage,
                     "one_shot_path_m": one_shot.path_length, "views": replanned.n_views,
                     "coverage": replanned.coverage, "path_m": replanned.path_length,
                     "replans": len(replanned.replans), "replanning_s": replanned.timings.get("replanning", 0.0),
                     "views_added": sum(r.views_added for r in replanned.replans),
                     "views_dropped": sum(r.views_dropped for r in replanned.replans)})
    return rows


def _run(function, cases, argument, replan_after, workers) -> pd.DataFrame:
    from tqdm.auto import tqdm

    rows = []
    with ProcessPoolExecutor(workers) as pool:
        for case_rows in tqdm(pool.map(function, cases, [argument] * len(cases), [replan_after] * len(cases)),
                              total=len(cases), unit="case"):
            rows += case_rows
    return pd.DataFrame(rows)


def calibration_summary(raw: pd.DataFrame) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(per view space and ratio; per view space the largest passing ratio)."""
    raw = raw.assign(ratio_to_optimum=raw["views"] / raw["optimum_views"])
    summary = raw.groupby(["view_space", "ratio"]).agg(
        cases=("views", "size"), views_mean=("views", "mean"), optimum_views_mean=("optimum_views", "mean"),
        ratio_to_optimum=("ratio_to_optimum", "mean"), coverage_mean=("coverage", "mean"),
        coverage_min=("coverage", "min"), views_added=("views_added", "mean"),
        views_dropped=("views_dropped", "mean")).reset_index()
    passing = summary[(summary["coverage_mean"] >= ASKED + MARGIN) & (summary["coverage_min"] >= ASKED - 0.01 + MARGIN)]
    chosen = passing.loc[passing.groupby("view_space")["ratio"].idxmax()].reset_index(drop=True)
    return summary, chosen


def evaluation_summary(raw: pd.DataFrame) -> pd.DataFrame:
    raw = pd.concat([raw, raw.assign(source="all")], ignore_index=True)
    raw = raw.assign(ratio=raw["views"] / raw["optimum_views"], one_shot_ratio=raw["one_shot_views"] / raw["optimum_views"],
                     path_ratio=raw["path_m"] / raw["one_shot_path_m"], below_97=raw["coverage"] < 0.97)
    summary = raw.groupby(["source", "view_space", "target"]).agg(
        cases=("views", "size"), optimum_views=("optimum_views", "mean"), one_shot_views=("one_shot_views", "mean"),
        one_shot_ratio=("one_shot_ratio", "mean"), one_shot_coverage=("one_shot_coverage", "mean"),
        views=("views", "mean"), ratio=("ratio", "mean"), coverage_mean=("coverage", "mean"),
        coverage_min=("coverage", "min"), cases_below_97pct=("below_97", "sum"), path_ratio=("path_ratio", "mean"),
        replans=("replans", "mean"), replanning_s=("replanning_s", "mean")).reset_index()
    summary.insert(7, "ratio_of_means", summary["views"] / summary["optimum_views"])
    for column in ("one_shot_coverage", "coverage_mean", "coverage_min"):
        summary[column] *= 100
    return summary


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mode", choices=["calibrate", "evaluate"], default="calibrate")
    parser.add_argument("--seeds", nargs="+", type=int, default=None,
                        help="generated seeds (calibrate: 10 11 12; evaluate: 0 1 2 plus the bundled pair)")
    parser.add_argument("--ratios", nargs="+", type=float, default=list(RATIOS))
    parser.add_argument("--targets", nargs="+", type=float, default=list(TARGETS))
    parser.add_argument("--replan-after", type=int, default=1)
    parser.add_argument("--view-spaces", nargs="+", default=list(plants.VIEW_SPACES))
    parser.add_argument("--rotations", nargs="+", type=float, default=list(plants.ROTATIONS))
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--output", default=None, help="CSV of every row")
    parser.add_argument("--results", default=str(RESULTS), metavar="DIR")
    args = parser.parse_args()
    calibrate = args.mode == "calibrate"
    seeds = tuple(args.seeds or ((10, 11, 12) if calibrate else plants.GENERATED_SEEDS))
    instances = plants.generated_instances(seeds=seeds)
    if not calibrate:
        instances.append(plants.bundled_instance())
    cases = plants.case_list(instances, tuple(args.view_spaces), rotations=tuple(args.rotations))
    started = time.perf_counter()
    raw = _run(_calibrate_case if calibrate else _evaluate_case, cases,
               tuple(args.ratios) if calibrate else tuple(args.targets), args.replan_after, args.workers)
    if args.output:
        raw.to_csv(args.output, index=False)
    seconds = time.perf_counter() - started
    if calibrate:
        summary, chosen = calibration_summary(raw)
        for table in (summary, chosen):
            table[["coverage_mean", "coverage_min"]] *= 100
        tables = [(f"largest miss ratio with mean >= {100 * (ASKED + MARGIN):g} % and no case below "
                   f"{100 * (ASKED - 0.01 + MARGIN):g} % (coverage in %)", chosen),
                  ("per view space and miss ratio (coverage in %)", summary)]
    else:
        tables = [("one-shot and re-planned plans beside the exact optimum (coverage in %; path_ratio: re-planned "
                   "path / one-shot path; replanning_s: seconds of re-planning per case)", evaluation_summary(raw))]
    pd.set_option("display.width", 250)
    for title, table in tables:
        print(f"\n{title}:\n{table.round(4).to_string(index=False)}")
    what = (f"{len(cases)} cases, seeds {list(seeds)}, re-planning after every {args.replan_after} view(s), "
            f"{seconds:.0f} s on {args.workers} workers; "
            + (f"miss ratios {list(args.ratios)}" if calibrate else
               f"targets {list(args.targets)}, one-shot rule {CALIBRATED_MISS_RATIO}, re-planning rule "
               f"{CALIBRATED_REPLAN_MISS_RATIO}"))
    write_results(Path(args.results) / f"replanning_{args.mode}.md", tables, what)


if __name__ == "__main__":
    main()
