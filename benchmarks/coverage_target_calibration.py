"""How a coverage target on the *predicted* planning surface relates to the *true* coverage
(calibration), and whether a requested true coverage is delivered (evaluation).

``--mode calibrate`` (default seeds 10, 11, 12: disjoint from the evaluation seeds 0, 1, 2):
each case's warm-up + registration is shared by every planning target t in --targets; the plan for
t sees ceil(t x coverable) planning voxels (``selection.planning_miss_ratio = 1``: the target is
applied to the prediction as it is). Printed per view space and planning target: views, true
coverage of the oracle (mean, min), share of cases reaching 97 / 98 / 99 %, and for each asked
true target (--asked) the smallest planning target whose mean reaches it with no case more than
one point below, as a miss ratio (1 - planning) / (1 - asked).

``--mode evaluate`` (default seeds 0, 1, 2 plus the bundled real pair on its own rows): the plan
for each asked true target with the library's calibrated rule (``planning_miss_ratio = None``)
beside the exact optimum with perfect knowledge for the same target (same initial view), and the
registration's Chamfer to the ground truth. Printed per view space and target: views, optimum
views and their ratio, true coverage (mean, min, cases below target - 1 point).

Both modes use the 36-case protocol per view space (rotations 0 and 45, initial views 17 / 8 / 21)
unless --rotations says otherwise, and run cases on --workers processes.

Usage:
    python benchmarks/coverage_target_calibration.py --mode calibrate [--seeds 10 11 12]
    python benchmarks/coverage_target_calibration.py --mode evaluate [--targets 0.95 0.98 0.99 1.0]
"""

from __future__ import annotations

import argparse
import shlex
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pandas as pd

from tpvp.config import make_config, with_overrides
from tpvp.io import atomic_write_text
from tpvp.experiments import plants

RESULTS = Path(__file__).resolve().parent / "results"
CALIBRATION_TARGETS = (0.95, 0.97, 0.98, 0.985, 0.99, 0.995, 1.0)
EVALUATION_TARGETS = (0.95, 0.98, 0.99, 1.0)


def _base_config(nbv_method):
    return make_config("plant", {"nbv.method": nbv_method} if nbv_method else {})


def _calibrate_case(case, targets, nbv_method=None) -> list[dict]:
    from tpvp.experiments.single_plant import build_scene, run_case, transfer
    from tpvp.jit import compile_kernels

    compile_kernels()
    config = case.config(_base_config(nbv_method))
    scene = build_scene(*case.instance.load(), config)
    shared = transfer(scene, config)
    rows = []
    for target in targets:
        result = run_case(scene, with_overrides(config, {
            "selection.coverage_target": target, "selection.planning_miss_ratio": 1.0}), transferred=shared)
        rows.append({**case.labels(), "target": target, "views": result.n_views, "coverage": result.coverage,
                     "path_length_m": result.path_length, "optimal": result.selection.optimal})
    return rows


def _evaluate_case(case, targets, nbv_method=None) -> list[dict]:
    from tpvp.experiments.frontier import coverage_frontier
    from tpvp.experiments.single_plant import build_scene, transfer
    from tpvp.jit import compile_kernels
    from tpvp.metrics import chamfer_distance

    compile_kernels()
    config = case.config(_base_config(nbv_method))
    scene = build_scene(*case.instance.load(), config)
    shared = transfer(scene, config)
    chamfer_mm = 1e3 * chamfer_distance(shared.alignment.warped, scene.current)
    frontier = coverage_frontier(scene, config, targets, transferred=shared)
    return [{**case.labels(), **row, "chamfer_truth_mm": chamfer_mm} for row in frontier.to_dict("records")]


def _run(function, cases, targets, workers, nbv_method=None) -> pd.DataFrame:
    from tqdm.auto import tqdm

    rows = []
    with ProcessPoolExecutor(workers) as pool:
        for case_rows in tqdm(pool.map(function, cases, [targets] * len(cases), [nbv_method] * len(cases)),
                              total=len(cases), unit="case"):
            rows += case_rows
    return pd.DataFrame(rows)


def calibration_summary(raw: pd.DataFrame, asked=(0.95, 0.98, 0.99)) -> tuple[pd.DataFrame, pd.DataFrame]:
    summary = raw.groupby(["view_space", "target"]).agg(
        cases=("views", "size"), views_mean=("views", "mean"), views_std=("views", "std"),
        coverage_mean=("coverage", "mean"), coverage_min=("coverage", "min"),
        reach_97=("coverage", lambda c: (c >= 0.97).mean()), reach_98=("coverage", lambda c: (c >= 0.98).mean()),
        reach_99=("coverage", lambda c: (c >= 0.99).mean())).reset_index()
    rules = []
    for space, group in summary.groupby("view_space"):
        for want in asked:
            ok = group[(group["coverage_mean"] >= want) & (group["coverage_min"] >= want - 0.01)]
            planning = float(ok["target"].min()) if len(ok) else np.nan
            rules.append({"view_space": space, "asked": want, "smallest planning target": planning,
                          "miss ratio": (1 - planning) / (1 - want) if np.isfinite(planning) else np.nan})
    return summary, pd.DataFrame(rules)


def evaluation_summary(raw: pd.DataFrame) -> pd.DataFrame:
    raw = raw.assign(ratio=raw["views"] / raw["optimum_views"],
                     below=raw["coverage"] < raw["target"] - 0.01)
    summary = raw.groupby(["source", "view_space", "target"]).agg(
        cases=("views", "size"), views_mean=("views", "mean"), optimum_views_mean=("optimum_views", "mean"),
        ratio_mean=("ratio", "mean"), coverage_mean=("coverage", "mean"), coverage_min=("coverage", "min"),
        cases_below_target_minus_1pt=("below", "sum"), chamfer_truth_mm=("chamfer_truth_mm", "mean"))
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
    raw = _run(_calibrate_case if calibrate else _evaluate_case, cases, targets, args.workers, args.nbv)
    if args.output:
        raw.to_csv(args.output, index=False)
    print(f"{args.mode}: {len(cases)} cases x {len(targets)} targets, seeds {list(seeds)}, "
          f"warm-up NBV {args.nbv or make_config('plant').nbv.method}, "
          f"{time.perf_counter() - started:.0f} s on {args.workers} workers")
    pd.set_option("display.width", 200)
    tables = []
    if calibrate:
        summary, rules = calibration_summary(raw)
        tables = [("summary (coverage in %)", summary),
                  ("smallest planning target with mean >= asked and no case below asked - 1 point", rules)]
    else:
        tables = [("evaluation (coverage in %)", evaluation_summary(raw))]
    for _, table in tables:
        for column in ("coverage_mean", "coverage_min"):
            if column in table:
                table[column] *= 100
    for title, table in tables:
        print(f"\n{title}:\n{table.round(4).to_string(index=False)}")
    nbv = f"_{args.nbv}" if args.nbv else ""
    _write_results(Path(args.results) / f"coverage_target_{args.mode}{nbv}.md", tables,
                   f"{len(cases)} cases x {len(targets)} targets, seeds {list(seeds)}, warm-up NBV "
                   f"{args.nbv or make_config('plant').nbv.method}")


def _write_results(path: Path, tables, what: str) -> None:
    """The tables as Markdown with the command that made them (through the library's atomic writer)."""
    command = "python " + " ".join(shlex.quote(a) for a in [Path(sys.argv[0]).as_posix(), *sys.argv[1:]])
    text = [f"# {path.stem}", "", f"Made by `{command}` on {datetime.now(timezone.utc):%Y-%m-%d} ({what}).", ""]
    for title, table in tables:
        rows = [[f"{v:.4g}" if isinstance(v, (float, np.floating)) else str(v) for v in row]
                for row in table.itertuples(index=False)]
        text += [f"## {title}", "", "| " + " | ".join(map(str, table.columns)) + " |",
                 "|" + "---|" * len(table.columns), *("| " + " | ".join(row) + " |" for row in rows), ""]
    atomic_write_text(path, "\n".join(text))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
