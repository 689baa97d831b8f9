"""Block-wise NBV (the greenhouse-row sequential baseline): seconds per iteration, coverage, path.

Run from the repository root::

    python benchmarks/blockwise_nbv_bench.py                   # room1 seed 0 session 1, 500 views
    python benchmarks/blockwise_nbv_bench.py --budget 100      # shorter
    python benchmarks/blockwise_nbv_bench.py --separate 100 300  # also fresh runs of these budgets
    python benchmarks/blockwise_nbv_bench.py --no-oracle       # skip the oracle (~2 min at 1 cm)

Scene: a generated row (``generate_row(room, seed, session)``) voxelised at 1 cm, the room's 1,000
candidate positions, sensor range 2 m, default ``BlockwiseNbvConfig`` (10 blocks, 50 look-ats per
step, 5 cm map, block quotas of a 500-view plan: ``--plan``). One run of ``--budget`` views, read
at view counts up to the budget: the paper's protocol (prefixes of one run). ``--separate`` adds
fresh runs with ``plan_views=None`` (quotas of their own budget, every block visited), the other
reading of the paper's 100/300/500 rows.

Per iteration: ``plan s`` = frontier, targets, pairing and gains of the block's candidates;
``step s`` = the whole iteration, including the simulated observation (the ground-truth sensor)
and the map update. Target: <= 0.2 s per iteration on 2 cores. Coverage = share of the truth voxels
seen by the start view and the first n views, raw and normalised by the greenhouse oracle
(docs/greenhouse.md#oracle). Path = Euclidean, from the start view (passive view 0), in execution
order. Kernels are compiled (or loaded from numba's cache) by a 2-view run before timing.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

try:
    import tpvp  # noqa: F401
except ImportError:  # not installed: run from a checkout
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numba
import pandas as pd

from tpvp.nbv.blockwise import BlockwiseNbvConfig, blockwise_nbv
from tpvp.scene import voxels
from tpvp.scene.boxes import room_config
from tpvp.scene.grid import build_grid
from tpvp.sensor.sensor import SensorConfig
from tpvp.synthetic.greenhouse import generate_row
from tpvp.visibility.oracle import greenhouse_oracle

TARGET_S = 0.2


def checkpoints(budget: int) -> list[int]:
    marks = [0, 10, 25, 50, 100, 200, 300, 400, 500, 750, 1000]
    return sorted({m for m in marks if m <= budget} | {budget})


def table_of(result, oracle, marks, label):
    raw = result.coverage_curve()
    cov = result.coverage_curve(oracle) if oracle is not None else None
    rows = []
    for n in marks:
        rows.append({
            "run": label,
            "views": n,
            "coverage % (all voxels)": 100 * raw[n],
            "coverage % (oracle)": None if cov is None else 100 * cov[n],
            "path m": result.path_after(n),
            "blocks visited": int(result.block[n - 1]) + 1 if n else 0,
        })
    return rows


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--room", default="room1")
    parser.add_argument("--seed", type=int, default=0, help="row generator seed")
    parser.add_argument("--session", type=int, default=1)
    parser.add_argument("--gt", type=float, default=0.01, help="ground-truth voxel (m)")
    parser.add_argument("--budget", type=int, default=500)
    parser.add_argument("--plan", type=int, default=500, help="plan_views of the one run")
    parser.add_argument("--target-margin", type=lambda v: None if v.lower() == "none" else float(v),
                        default=BlockwiseNbvConfig.target_margin, help="m, or 'none' (whole plant box)")
    parser.add_argument("--separate", type=int, nargs="*", default=[], help="fresh runs of these budgets")
    parser.add_argument("--map-resolution", type=float, default=BlockwiseNbvConfig.map_resolution)
    parser.add_argument("--start", default="first_passive", choices=["first_passive", "passive", "none"])
    parser.add_argument("--no-oracle", action="store_true")
    parser.add_argument("--oracle-cache", type=Path, help="load / save the oracle ids (.npy)")
    args = parser.parse_args()

    room = room_config(args.room)
    started = time.perf_counter()
    row = generate_row(args.room, seed=args.seed, session=args.session)
    grid = build_grid(voxels.voxelise(row.points, args.gt), args.gt)
    print(f"{args.room} seed {args.seed} session {args.session}: {grid.size:,} truth voxels at {args.gt} m "
          f"({time.perf_counter() - started:.1f} s)")
    oracle = None
    if not args.no_oracle:
        if args.oracle_cache is not None and args.oracle_cache.is_file():
            oracle = np.load(args.oracle_cache)
        else:
            started = time.perf_counter()
            oracle = greenhouse_oracle(grid, room.view_box.grid(0.1), max_range=2.0, progress=False)
            print(f"oracle: {len(oracle):,} visible voxels ({100 * len(oracle) / grid.size:.1f} %), "
                  f"{time.perf_counter() - started:.0f} s")
            if args.oracle_cache is not None:
                np.save(args.oracle_cache, oracle)

    sensor = SensorConfig(max_range=2.0)
    config = BlockwiseNbvConfig(map_resolution=args.map_resolution, plan_views=args.plan,
                                target_margin=args.target_margin)
    started = time.perf_counter()
    blockwise_nbv(grid, room, 2, config, sensor, start_views=args.start, progress=False)
    print(f"compile / warm-up {time.perf_counter() - started:.1f} s; numba threads {numba.get_num_threads()}, "
          f"cpus {os.cpu_count()}")

    runs = [(args.budget, f"one run of {args.budget}", config)] + [
        (b, f"fresh run of {b}", replace(config, plan_views=None)) for b in args.separate]
    rows, timing = [], []
    for budget, label, cfg in runs:
        started = time.perf_counter()
        result = blockwise_nbv(grid, room, budget, cfg, sensor, start_views=args.start, seed=0, progress=False)
        wall = time.perf_counter() - started
        marks = checkpoints(budget) if budget == args.budget else [budget]
        rows += table_of(result, oracle, marks, label)
        timing.append({
            "run": label, "views": budget, "wall s": wall,
            "plan s mean": result.plan_seconds.mean(), "plan s max": result.plan_seconds.max(),
            "step s mean": result.seconds.mean(), "step s p95": np.percentile(result.seconds, 95),
            "step s max": result.seconds.max(),
            "target": f"<= {TARGET_S} s", "met": "yes" if result.seconds.mean() <= TARGET_S else "no",
            "surface-frontier targets %": 100 * result.frontier_targets.mean() / config.look_ats_per_block,
        })
    print()
    print(pd.DataFrame(timing).to_string(index=False, float_format=lambda x: f"{x:.3f}"))
    print()
    print(pd.DataFrame(rows).to_string(index=False, float_format=lambda x: f"{x:.2f}"))


if __name__ == "__main__":
    main()
