"""Where the time of one greenhouse-row case goes, against the issue's goals on 2 cores.

One generated row pair (default room1, sessions 0 -> 1, 1 cm ground truth): the oracle (computed,
not read from a cache), the passive sweep, the warp-field registration, inflation, look-at
targets, visibility of the 800 candidates on the planning surface and set cover at each covering
voxel, the band path, execution; then the whole case at 4 cm from the scene. Each figure is printed
beside its goal and the paper's time (14 cores), with the ratio to the goal (< 1: met).

    python benchmarks/row_case_bench.py [--room room1] [--pair 0] [--resolutions 0.10 0.05 0.04 0.03]
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

from tpvp.config_loading import make_config
from tpvp.simulate import greenhouse
from tpvp.simulate.row_cases import RowCase
from tpvp.pipeline.jit import compile_kernels

GOALS = {"oracle": 120.0, "registration": 10.0, "visibility@3cm": 30.0, "path": 5.0, "case@4cm": 180.0}
PAPER = {"oracle": "hours", "registration": "3-8", "visibility@10cm": "250", "visibility@5cm": "700",
         "visibility@4cm": "1200", "visibility@3cm": "2000", "selection@4cm": "~1", "path": "2-10"}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--room", default="room1", choices=["room1", "room4"])
    ap.add_argument("--pair", type=int, default=0)
    ap.add_argument("--resolutions", type=float, nargs="+", default=[0.10, 0.05, 0.04, 0.03])
    args = ap.parse_args(argv)

    print(f"numba compile / cache load {compile_kernels():.1f} s (not counted)")
    config = make_config("row", {"view_space": args.room})
    previous, current = RowCase(args.room, args.pair).load()
    figures = {}
    t = time.perf_counter()
    scene = greenhouse.build_row_scene(previous, current, config, cache_dir=False)
    figures["scene (oracle included)"] = time.perf_counter() - t
    figures["oracle"] = scene.timings["oracle"]
    transfer = greenhouse.row_transfer(scene, config)
    figures["registration"] = transfer.timings["registration"]
    figures["inflation"] = transfer.timings["inflation"]
    views = {}
    for resolution in args.resolutions:
        case_config = replace(config, selection=replace(config.selection, cover_resolution=resolution))
        result = greenhouse.run_row_case(scene, case_config, transferred=transfer)
        label = f"{100 * resolution:g}cm"
        figures[f"visibility@{label}"] = result.timings["visibility"]
        figures[f"selection@{label}"] = result.timings["selection"]
        figures[f"path@{label}"] = result.timings["path"]
        views[label] = (result.n_views, result.coverage, result.path_length, result.path.gap)
    figures["targets"] = result.timings["targets"]
    figures["path"] = max(v for k, v in figures.items() if k.startswith("path@"))
    t = time.perf_counter()
    greenhouse.run_row_case(scene, replace(config, selection=replace(config.selection, cover_resolution=0.04)))
    figures["case@4cm"] = time.perf_counter() - t  # registration to execution, scene and oracle apart

    print(f"\n{args.room} sessions {args.pair}->{args.pair + 1}: {int(scene.grid.countable.sum()):,} voxels, "
          f"oracle {len(scene.oracle):,}")
    print(f"{'stage':26} {'seconds':>9} {'goal':>7} {'ratio':>6} {'paper (14 cores)':>17}")
    for name, seconds in figures.items():
        goal = GOALS.get(name)
        ratio = f"{seconds / goal:6.2f}" if goal else ""
        print(f"{name:26} {seconds:9.2f} {goal or '':>7} {ratio:>6} {PAPER.get(name, ''):>17}")
    print(f"\n{'covering voxel':15} {'views':>6} {'coverage %':>11} {'path m':>8} {'path gap %':>11}")
    for label, (n, coverage, length, gap) in views.items():
        print(f"{label:15} {n:6d} {100 * coverage:11.2f} {length:8.2f} {100 * gap:11.2f}")


if __name__ == "__main__":
    main()
