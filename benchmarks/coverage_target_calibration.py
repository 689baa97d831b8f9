"""How a coverage target on the *predicted* planning surface relates to the *true* coverage
(calibration), and whether a requested true coverage is delivered (evaluation).

``--mode calibrate`` (default seeds 10, 11, 12: disjoint from the evaluation seeds 0, 1, 2):
each case's warm-up + registration + planning surface (inflation, visibility, voxel classes) is
shared by every planning target t in --targets and every class-weight combination of the grid
(``surface_weights``, :func:`weight_grid`: the uncertain classes weighted down or up, and the
unweighted surface); the plan for t sees t of the coverable planning weight
(``selection.planning_miss_ratio = 1``: the target is applied to the prediction as it is), only
the selection runs per grid point (no path: the views are the selected ones). Printed per view
space, weights and planning target: views, views / the exact optimum for 98 % (perfect knowledge,
same initial view), true coverage of the oracle (mean, min), share of cases reaching 97 / 98 /
99 %; per weights and view space the smallest planning target whose mean reaches 98 % + MARGIN
with no case below 97 % + MARGIN (and a miss ratio within MAX_MISS_RATIO), as a miss ratio
(1 - planning) / (1 - 0.98); and the chosen
rule: the weights with the smallest sum over the view spaces of views / optimum at their smallest
passing targets (ties: fewer views).

``--mode evaluate`` (default seeds 0, 1, 2 plus the bundled real pair on its own rows): the plan
for each asked true target with the library's calibrated rule (``planning_miss_ratio = None``)
beside the exact optimum with perfect knowledge for the same target (same initial view), and the
registration's Chamfer to the ground truth. Printed per view space and target: views, optimum
views and their ratio, true coverage (mean, min, cases below target - 1 point).

Both modes use the 36-case protocol per view space (rotations 0 and 45, initial views 17 / 8 / 21)
unless --rotations says otherwise, and run cases on --workers processes.

Usage:
    python benchmarks/coverage_target_calibration.py --mode calibrate [--seeds 10 11 12]
    python benchmarks/coverage_target_calibration.py --mode evaluate [--targets 0.95 0.98 0.99 1.0] [--weights on]
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd

from tpvp.config_loading import make_config, with_overrides
from tpvp.setcover.config import CALIBRATED_MISS_RATIO
from tpvp.experiments import plants
from results_file import write_results

RESULTS = Path(__file__).resolve().parent / "results"
CALIBRATION_TARGETS = (0.98, 0.985, 0.9875, 0.99, 0.9925, 0.995, 0.99625, 0.9975, 0.99875, 0.9995)
EVALUATION_TARGETS = (0.95, 0.98, 0.99, 1.0)
# The class-weight grid of --mode calibrate: observed / transferred near / transferred far /
# inflation weights, @ near_voxels (how far from Q a transferred voxel stays "near"), "area": times
# each voxel's sub-voxel count. The uncertain classes weighted down (the rule's idea), up
# (observed < 1), and by area; then the unweighted surface. A first grid on the same seeds (only
# observed < 1, far and inflation 1 or 2, 0.5 or 1) did no better than the unweighted surface, and
# the far and inflation classes hold under 1 % of the voxels at near_voxels 2.
DOWN_WEIGHTS = ((0.5, 0.25), (0.5, 0.1), (0.25, 0.25), (0.25, 0.1), (0.1, 0.1))  # (near, far)
DOWN_INFLATION = 0.1
NEAR_VOXELS = (1.0, 2.0)
UP_OBSERVED = (0.25, 0.5)
AREA_WEIGHTS = ((1.0, 1.0, 1.0, 1.0), (1.0, 0.5, 0.25, 0.1), (1.0, 0.25, 0.25, 0.1), (0.5, 1.0, 1.0, 1.0))
ASKED = 0.98
# Points of true coverage the calibration seeds must clear above the requirement (mean >= 98 %,
# no case below 97 %): some room for the seed-to-seed spread that made the first sphere rule miss
# on the evaluation seeds (docs/results.md, "Coverage target").
MARGIN = 0.001
# Largest miss ratio a rule may take per view space: with the prior warm-up the unweighted sphere
# needs r <= 0.25 on these seeds (results/coverage_target_calibrate_prior.md), and a rule must hold
# for either warm-up NBV; this grid is run with the default (geometric) warm-up only.
MAX_MISS_RATIO = {"sphere": 0.25}


def weight_grid():
    """Every class-weight combination of the calibration, then the unweighted surface (None)."""
    names = ("observed", "transferred_near", "transferred_far", "inflation")

    def combo(weights, near_voxels=2.0, area=False):
        return {**dict(zip(names, weights)), "near_voxels": near_voxels, "area": area}

    down = [combo((1.0, n, f, DOWN_INFLATION), k) for k in NEAR_VOXELS for n, f in DOWN_WEIGHTS]
    up = [combo((o, 1.0, 1.0, 1.0)) for o in UP_OBSERVED]
    area = [combo(w, area=True) for w in AREA_WEIGHTS]
    return [*down, *up, *area, None]


def _weights_label(weights) -> str:
    if weights is None:
        return "unweighted"
    return "/".join(f"{weights[k]:g}" for k in ("observed", "transferred_near", "transferred_far", "inflation")) \
        + f" @{weights['near_voxels']:g}" + (" area" if weights["area"] else "")


def selection_on_prediction(scene, config, shared, surface, target: float, overrides=None) -> tuple:
    """``(views, true coverage, proven optimal)`` of the selection alone (no path) for planning
    target ``target`` applied to the planning ``surface`` as it is (``planning_miss_ratio = 1``),
    executed views included; ``overrides``: more configuration keys."""
    from tpvp.simulate.single_plant import known
    from tpvp.pipeline.plan import selection_problem
    from tpvp.setcover.methods import select_views
    from tpvp.visibility import coverage_ratio, covered_voxels

    planned = with_overrides(config, {**(overrides or {}), "selection.coverage_target": target,
                                      "selection.planning_miss_ratio": 1.0})
    selection = select_views(selection_problem(known(scene), planned, shared, surface), planned.selection)
    views = list(shared.executed) + [int(v) for v in selection.selected]
    return len(views), coverage_ratio(covered_voxels(scene.truth_visibility, views), scene.oracle), selection.optimal


def _calibrate_case(case, targets, overrides) -> list[dict]:
    from tpvp.simulate.optimum import optimum
    from tpvp.simulate.single_plant import build_scene, known, transfer
    from tpvp.pipeline.plan import planning_surface
    from tpvp.inflation.weights import surface_area, surface_classes
    from tpvp.pipeline.jit import compile_kernels

    compile_kernels()
    config = case.config(make_config("plant", overrides))
    scene = build_scene(*case.instance.load(), config)
    shared = transfer(scene, config)
    surface = planning_surface(known(scene), config, shared)
    # every weighting of the grid reads the classes (per near_voxels, below) and the area
    surface = replace(surface, area=surface_area(surface.grid.keys, surface.grid.resolution, surface.inflated.planning))
    best = int(optimum(scene, config, targets=(ASKED,))["views"].iloc[0])
    rows = []
    for weights in weight_grid():
        weighting = ({"surface_weights.enabled": False} if weights is None
                     else {"surface_weights.enabled": True, **{f"surface_weights.{k}": v for k, v in weights.items()}})
        near_voxels = 2.0 if weights is None else weights["near_voxels"]
        classes = surface_classes(surface.grid.keys, surface.grid.resolution, shared.alignment.warped, shared.coarse,
                                  near_voxels * surface.grid.resolution)
        surface = replace(surface, classes=classes)
        shares = np.bincount(classes, minlength=4) / len(classes)
        for target in targets:
            views, coverage, optimal = selection_on_prediction(scene, config, shared, surface, target, weighting)
            rows.append({**case.labels(), "weights": _weights_label(weights), "target": target,
                         "views": views, "optimum_views": best, "coverage": coverage, "optimal": optimal,
                         **{f"share_{name}": share for name, share in zip(("observed", "near", "far", "inflation"),
                                                                          shares)}})
    return rows


def _evaluate_case(case, targets, overrides) -> list[dict]:
    from tpvp.simulate.frontier import coverage_frontier
    from tpvp.simulate.single_plant import build_scene, transfer
    from tpvp.pipeline.jit import compile_kernels
    from tpvp.metrics import chamfer_distance

    compile_kernels()
    config = case.config(make_config("plant", overrides))
    scene = build_scene(*case.instance.load(), config)
    shared = transfer(scene, config)
    chamfer_mm = 1e3 * chamfer_distance(shared.alignment.warped, scene.current)
    frontier = coverage_frontier(scene, config, targets, transferred=shared)
    return [{**case.labels(), **row, "chamfer_truth_mm": chamfer_mm} for row in frontier.to_dict("records")]


def _run(function, cases, targets, workers, overrides) -> pd.DataFrame:
    from tqdm.auto import tqdm

    rows = []
    with ProcessPoolExecutor(workers) as pool:
        for case_rows in tqdm(pool.map(function, cases, [targets] * len(cases), [overrides] * len(cases)),
                              total=len(cases), unit="case"):
            rows += case_rows
    return pd.DataFrame(rows)


def calibration_summary(raw: pd.DataFrame, asked=ASKED, margin=MARGIN):
    """(summary per view space, weights and planning target; per weights and view space the
    smallest passing planning target; the chosen weights with their targets per view space)."""
    raw = raw.assign(ratio=raw["views"] / raw["optimum_views"])
    summary = raw.groupby(["view_space", "weights", "target"], sort=False).agg(
        cases=("views", "size"), views_mean=("views", "mean"), ratio_mean=("ratio", "mean"),
        coverage_mean=("coverage", "mean"), coverage_min=("coverage", "min"),
        reach_97=("coverage", lambda c: (c >= 0.97).mean()), reach_98=("coverage", lambda c: (c >= 0.98).mean()),
        reach_99=("coverage", lambda c: (c >= 0.99).mean())).reset_index()
    rules = []
    for (weights, space), group in summary.groupby(["weights", "view_space"], sort=False):
        lowest = 1 - MAX_MISS_RATIO.get(space, np.inf) * (1 - asked)
        ok = group[(group["coverage_mean"] >= asked + margin) & (group["coverage_min"] >= asked - 0.01 + margin)
                   & (group["target"] >= lowest - 1e-12)]
        row = ok.loc[ok["target"].idxmin()] if len(ok) else None
        rules.append({"weights": weights, "view_space": space,
                      "smallest planning target": float(row["target"]) if row is not None else np.nan,
                      "miss ratio": (1 - float(row["target"])) / (1 - asked) if row is not None else np.nan,
                      "views_mean": float(row["views_mean"]) if row is not None else np.nan,
                      "ratio_mean": float(row["ratio_mean"]) if row is not None else np.nan,
                      "coverage_mean": float(row["coverage_mean"]) if row is not None else np.nan,
                      "coverage_min": float(row["coverage_min"]) if row is not None else np.nan})
    rules = pd.DataFrame(rules)
    score = rules.groupby("weights", sort=False).agg(ratio_sum=("ratio_mean", lambda r: r.sum(min_count=len(r))),
                                                     views_sum=("views_mean", "sum"))
    score = score.dropna().sort_values(["ratio_sum", "views_sum"], kind="stable")
    chosen = rules[rules["weights"] == score.index[0]] if len(score) else rules.iloc[:0]
    return summary, rules, chosen.reset_index(drop=True)


def evaluation_summary(raw: pd.DataFrame) -> pd.DataFrame:
    raw = raw.assign(ratio=raw["views"] / raw["optimum_views"],
                     below=raw["coverage"] < raw["target"] - 0.01, below_97=raw["coverage"] < 0.97)
    # Every case of a view space together (the 42-case protocol: generated and bundled) as source "all".
    raw = pd.concat([raw, raw.assign(source="all")], ignore_index=True)
    summary = raw.groupby(["source", "view_space", "target"]).agg(
        cases=("views", "size"), views_mean=("views", "mean"), optimum_views_mean=("optimum_views", "mean"),
        ratio_mean=("ratio", "mean"), coverage_mean=("coverage", "mean"), coverage_min=("coverage", "min"),
        cases_below_target_minus_1pt=("below", "sum"), cases_below_97pct=("below_97", "sum"),
        chamfer_truth_mm=("chamfer_truth_mm", "mean"))
    summary.insert(3, "ratio_of_means", summary["views_mean"] / summary["optimum_views_mean"])
    return summary.reset_index()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mode", choices=["calibrate", "evaluate"], default="calibrate")
    parser.add_argument("--seeds", nargs="+", type=int, default=None,
                        help="generated seeds (calibrate: 10 11 12; evaluate: 0 1 2 plus the bundled pair)")
    parser.add_argument("--targets", nargs="+", type=float, default=None)
    parser.add_argument("--view-spaces", nargs="+", default=list(plants.VIEW_SPACES))
    parser.add_argument("--rotations", nargs="+", type=float, default=list(plants.ROTATIONS))
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--nbv", default=None, help="warm-up NBV method (default: the paper configuration's)")
    parser.add_argument("--weights", choices=["on", "off"], default=None,
                        help="evaluate: the planning surface's class weights (surface_weights.enabled; default: "
                             "the library's, off); results file coverage_target_evaluate_weighted.md when on")
    parser.add_argument("--output", default=None, help="CSV of every (case, target) row")
    parser.add_argument("--results", default=str(RESULTS), metavar="DIR",
                        help="folder of the result tables, coverage_target_<mode>[_<nbv>].md with the command "
                             "that made them (default: %(default)s)")
    args = parser.parse_args()
    calibrate = args.mode == "calibrate"
    seeds = tuple(args.seeds or ((10, 11, 12) if calibrate else plants.GENERATED_SEEDS))
    targets = tuple(args.targets or (CALIBRATION_TARGETS if calibrate else EVALUATION_TARGETS))
    instances = plants.generated_instances(seeds=seeds)
    if not calibrate:
        instances.append(plants.bundled_instance())
    cases = plants.case_list(instances, tuple(args.view_spaces), rotations=tuple(args.rotations))
    started = time.perf_counter()
    overrides = {"nbv.method": args.nbv} if args.nbv else {}
    if args.weights:
        overrides["surface_weights.enabled"] = args.weights == "on"
    raw = _run(_calibrate_case if calibrate else _evaluate_case, cases, targets, args.workers, overrides)
    if args.output:
        raw.to_csv(args.output, index=False)
    print(f"{args.mode}: {len(cases)} cases x {len(targets)} targets, seeds {list(seeds)}, "
          f"warm-up NBV {args.nbv or make_config('plant').nbv.method}, "
          f"{time.perf_counter() - started:.0f} s on {args.workers} workers")
    pd.set_option("display.width", 200)
    tables = []
    if calibrate:
        summary, rules, chosen = calibration_summary(raw)
        passing = (f"mean >= {100 * (ASKED + MARGIN):g} % and no case below {100 * (ASKED - 0.01 + MARGIN):g} %, "
                   f"miss ratio at most {MAX_MISS_RATIO}")
        tables = [("chosen rule: weights observed/near/far/inflation with the smallest sum of views / optimum "
                   "(coverage in %)", chosen),
                  (f"smallest planning target with {passing}, per weights (coverage in %)", rules),
                  ("summary (coverage in %)", summary)]
    else:
        tables = [("evaluation (coverage in %)", evaluation_summary(raw))]
    for _, table in tables:
        for column in ("coverage_mean", "coverage_min"):
            if column in table:
                table[column] *= 100
    for title, table in tables:
        print(f"\n{title}:\n{table.round(4).to_string(index=False)}")
    nbv = (f"_{args.nbv}" if args.nbv else "") + ("_weighted" if args.weights == "on" and not calibrate else "")
    what = (f"{len(cases)} cases x {len(targets)} targets, seeds {list(seeds)}, warm-up NBV "
            f"{args.nbv or make_config('plant').nbv.method}, {time.perf_counter() - started:.0f} s on {args.workers} workers")
    if calibrate:
        what += ("; calibrated: the class weights of surface_weights (observed/near/far/inflation @near_voxels: "
                 + ", ".join(_weights_label(w) for w in weight_grid()) + ") and the planning target per view "
                 "space, i.e. the miss ratio (1 - planning target) / (1 - 0.98)")
    else:
        what += f"; rule: {make_config('plant', overrides).surface_weights}, miss ratio {CALIBRATED_MISS_RATIO}"
    write_results(Path(args.results) / f"coverage_target_{args.mode}{nbv}.md", tables, what)


if __name__ == "__main__":
    main()
