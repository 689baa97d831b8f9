"""How a coverage target on the *predicted* planning surface relates to the *true* coverage.

For each case (generated pairs, both view spaces, rotation 0, initial views 17/8/21) one warm-up +
registration is shared by every planning target t in --targets; the plan for t is the fewest views
that see ceil(t x coverable) planning voxels (``selection.coverage_target``). Printed per view
space and target: views (mean ± std), true coverage of the oracle (mean, min), and the share of
cases reaching 97 / 98 / 99 %. Calibration uses seeds disjoint from the evaluation seeds of the
experiments (0, 1, 2): by default 10, 11, 12.

Usage: python benchmarks/coverage_target_calibration.py [--seeds 10 11 12] [--targets 0.95 0.97 0.98 0.99 0.995 1.0]
"""

from __future__ import annotations

import argparse
import time

import pandas as pd

from tpvp.config import make_config
from tpvp.experiments import plants
from tpvp.experiments.single_plant import build_scene, run_case, transfer
from tpvp.jit import compile_kernels


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", nargs="+", type=int, default=[10, 11, 12])
    parser.add_argument("--targets", nargs="+", type=float, default=[0.95, 0.97, 0.98, 0.99, 0.995, 1.0])
    parser.add_argument("--view-spaces", nargs="+", default=list(plants.VIEW_SPACES))
    parser.add_argument("--output", default=None, help="CSV of every (case, target) row")
    args = parser.parse_args()
    compile_kernels()
    base = make_config("plant")
    cases = plants.case_list(plants.generated_instances(seeds=tuple(args.seeds)), tuple(args.view_spaces),
                             rotations=(0.0,))
    rows = []
    t0 = time.perf_counter()
    for case in cases:
        config = case.config(base)
        scene = build_scene(*case.instance.load(), config)
        shared = transfer(scene, config)
        for target in args.targets:
            result = run_case(scene, make_config("plant", plants.to_flat(config) | {"selection.coverage_target": target}),
                              transferred=shared)
            rows.append({**case.labels(), "target": target, "views": result.n_views, "coverage": result.coverage,
                         "path_length_m": result.path_length, "optimal": result.selection.optimal})
    raw = pd.DataFrame(rows)
    if args.output:
        raw.to_csv(args.output, index=False)
    summary = raw.groupby(["view_space", "target"]).agg(
        cases=("views", "size"), views_mean=("views", "mean"), views_std=("views", "std"),
        coverage_mean=("coverage", "mean"), coverage_min=("coverage", "min"),
        reach_97=("coverage", lambda c: (c >= 0.97).mean()), reach_98=("coverage", lambda c: (c >= 0.98).mean()),
        reach_99=("coverage", lambda c: (c >= 0.99).mean()))
    for column in ("coverage_mean", "coverage_min"):
        summary[column] *= 100
    print(f"{len(cases)} cases x {len(args.targets)} targets, seeds {args.seeds}: {time.perf_counter() - t0:.0f} s")
    print(summary.round(3).to_string())


if __name__ == "__main__":
    main()
