"""Table I's Ours in the world as the robot sees it (issue 49): the paper's protocol (84 cases: the
generated tomato and maize pairs, seeds 0-2, and the bundled real pair, two rotations, three initial
views, both view spaces) planned with the planning frame of today's scan (``current``, the paper's)
and of the previous model with the first capture (``previous``, a real session's), under the sensor
noise profiles ``ideal``, ``arm-rgbd`` and ``phone-lidar`` (tpvp.sensor.noise). The true coverage is
measured exactly, as in Table I.

``--captures-seen``: where the noise's extra views go, on calibration cases apart from Table I's
(generated seeds 10 and 11, rotation 0, initial view 17): each profile with and without
``selection.captures_seen`` (every voxel holding a captured point credited to the view that captured
it); writes table1_world_captures_seen.md.

Usage:
    python benchmarks/table1_world.py [--quick | --captures-seen] [--workers 1] [--cache DIR] [--results FILE]
Writes benchmarks/results/table1_world.md (or FILE) with this command and prints the tables, and
the table as table1_world.csv beside it (notebook 02 shows it).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import pandas as pd

from results_file import write_results
from tpvp.io import atomic_write_text
from tpvp.config_loading import make_config
from tpvp.experiments import plants

RESULTS = Path(__file__).resolve().parent / "results" / "table1_world.md"
FRAMES = ("current", "previous")
PROFILES = ("ideal", "arm-rgbd", "phone-lidar")


def run(cases, workers: int, cache) -> pd.DataFrame:
    rows = []
    for frame in FRAMES:
        for profile in PROFILES:
            start = time.perf_counter()
            config = make_config("plant", {"scene.frame": frame, "sensor.noise": profile})
            raw = plants.run_experiments(cases, ["ours"], config, cache_dir=cache, workers=workers)
            print(f"frame {frame}, noise {profile}: {len(raw)} rows in {time.perf_counter() - start:.0f} s")
            rows.append(raw.assign(frame=frame, noise=profile))
    return pd.concat(rows, ignore_index=True)


def summary(raw: pd.DataFrame) -> pd.DataFrame:
    ours = raw[raw["method"] == "ours"]
    table = (ours.groupby(["view_space", "frame", "noise"], sort=False)
             .agg(cases=("views", "size"), views=("views", "mean"), coverage_pct=("coverage", "mean"),
                  lowest_coverage_pct=("coverage", "min"), path_m=("path_length_m", "mean"))
             .reset_index())
    table[["coverage_pct", "lowest_coverage_pct"]] *= 100
    base = table[(table["frame"] == "current") & (table["noise"] == "ideal")].set_index("view_space")
    table["views vs current/ideal"] = table["views"] / table["view_space"].map(base["views"])
    table["coverage vs current/ideal (points)"] = table["coverage_pct"] - table["view_space"].map(base["coverage_pct"])
    return table


def captures_seen(workers: int, cache) -> pd.DataFrame:
    cases = plants.case_list(plants.generated_instances(seeds=(10, 11)), rotations=(0.0,), initial_views=(17,))
    rows = []
    for profile in PROFILES:
        for seen in (False, True):
            config = make_config("plant", {"sensor.noise": profile, "selection.captures_seen": seen})
            raw = plants.run_experiments(cases, ["ours"], config, cache_dir=cache, workers=workers)
            for space, group in raw.groupby("view_space", sort=False):
                rows.append({"view_space": space, "noise": profile, "captures_seen": seen, "cases": len(group),
                             "views": group["views"].mean(), "coverage_pct": 100 * group["coverage"].mean(),
                             "lowest_coverage_pct": 100 * group["coverage"].min()})
    return pd.DataFrame(rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="the quick cases (one tomato and one maize pair)")
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--cache", type=Path, default=None, help="experiment cache (default: none)")
    parser.add_argument("--results", type=Path, default=None)
    parser.add_argument("--captures-seen", action="store_true",
                        help="each profile with and without selection.captures_seen on calibration seeds 10-11")
    args = parser.parse_args()
    start = time.perf_counter()
    if args.captures_seen:
        table = captures_seen(args.workers, args.cache)
        print(table.to_string(index=False))
        write_results(args.results or RESULTS.with_name("table1_world_captures_seen.md"),
                      [("Ours with and without the captured voxels credited to their view (calibration cases: "
                        "generated tomato and maize, seeds 10 and 11, rotation 0, initial view 17)", table)],
                      f"8 cases, {args.workers} worker(s), {(time.perf_counter() - start) / 60:.1f} min")
        return
    cases = plants.default_cases(quick=args.quick)
    table = summary(run(cases, args.workers, args.cache))
    print(table.to_string(index=False))
    what = (f"{len(cases)} cases{' (quick)' if args.quick else ''}, Ours, {args.workers} worker(s), "
            f"{(time.perf_counter() - start) / 60:.1f} min")
    results = args.results or (RESULTS.with_name("table1_world_quick.md") if args.quick else RESULTS)
    atomic_write_text(results.with_suffix(".csv"), table.to_csv(index=False, float_format="%.4g"))  # as printed
    write_results(results,
                  [("Ours by planning frame and sensor noise profile (means over the cases; coverage is the true "
                    "coverage of today's plant)", table)], what)


if __name__ == "__main__":
    main()
