"""Time of the coverage-effort frontier (``tpvp plan --frontier``) on the sphere, whose exact optimum
per target is the costly part: every target in one HiGHS model, warm-started from the next larger
target's views, within one time limit (``optimum(..., shared=True)``), against the anchor run in
the same process, each target alone with CBC at ``selection.set_cover.time_limit`` a target (how
the frontier solved it before issue 36).

The case: a generated plant (``--plant maize:1``, the largest of the generated seeds) scaled to a
real ``--size`` (0.6 m largest side) and planned at native scale on the sphere of ``--radius``
(0.8 m) around it, as ``tpvp plan --frontier --scale native --radius 0.8 --view-space sphere``
would. Target of issue 36: the whole frontier <= 60 s. Both runs must find the same optimum view
count wherever both proved it.

Usage: python benchmarks/frontier_bench.py [--plant maize:1] [--size 0.6] [--radius 0.8] [--no-anchor]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tpvp.config_loading import load_config, with_overrides  # noqa: E402
from tpvp.simulate.optimum import optimum  # noqa: E402
from tpvp.simulate.frontier import DEFAULT_TARGETS, OPTIMUM_SECONDS, coverage_frontier  # noqa: E402
from tpvp.simulate.single_plant import build_scene, transfer  # noqa: E402
from tpvp.pipeline.jit import compile_kernels, plant_pieces  # noqa: E402
from tpvp.synthetic.plants import generate_session_pair  # noqa: E402

TARGET_S = 60.0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--plant", default="maize:1", help="species:seed of the generated pair (default: %(default)s)")
    parser.add_argument("--size", type=float, default=0.6, help="largest side in metres (default: %(default)s)")
    parser.add_argument("--radius", type=float, default=0.8, help="view-sphere radius in metres (default: %(default)s)")
    parser.add_argument("--no-anchor", dest="anchor", action="store_false",
                        help="skip the per-target anchor (up to 60 s a target)")
    args = parser.parse_args(argv)
    species, seed = args.plant.split(":")
    pair = generate_session_pair(species, int(seed))
    extent = (pair.current.points.max(0) - pair.current.points.min(0)).max()
    scale = args.size / extent
    config = load_config("paper", {"view_space": "sphere", "scene.scale": "native", "scene.radius": args.radius})
    compile_kernels(*plant_pieces(config))
    scene = build_scene(pair.previous.points * scale, pair.current.points * scale, config)
    shared = transfer(scene, config)
    print(f"frontier_bench: {os.cpu_count()} cores, load {os.getloadavg()[0]:.2f}; {args.plant} scaled to "
          f"{args.size:g} m, sphere of {args.radius:g} m, {scene.grid.countable.sum()} plant voxels, "
          f"oracle {len(scene.oracle)} voxels, {len(scene.view_space.positions)} views")
    t = time.perf_counter()
    frontier = coverage_frontier(scene, config, DEFAULT_TARGETS, transferred=shared)
    seconds = time.perf_counter() - t
    t = time.perf_counter()
    optimum(scene, with_overrides(config, {"selection.set_cover.time_limit": OPTIMUM_SECONDS}), targets=DEFAULT_TARGETS,
            shared=True)
    shared_seconds = time.perf_counter() - t
    anchor = anchor_seconds = None
    if args.anchor:
        t = time.perf_counter()
        anchor = optimum(scene, config, targets=DEFAULT_TARGETS).set_index("target")
        anchor_seconds = time.perf_counter() - t
    print(f"the frontier's optimum: one model, {OPTIMUM_SECONDS:g} s for all targets")
    print("| target | plan views | optimum views | proven | anchor views | anchor proven |")
    print("|---|---|---|---|---|---|")
    same = True
    for row in frontier.itertuples():
        old = anchor.loc[row.target] if anchor is not None else None
        if old is not None and row.optimum_optimal and old["selection_optimal"]:
            same &= int(old["views"]) == row.optimum_views
        print(f"| {row.target:g} | {row.views} | {row.optimum_views} | {row.optimum_optimal} | "
              + (f"{int(old['views'])} | {bool(old['selection_optimal'])} |" if old is not None else "- | - |"))
    print(f"whole frontier (plans and the shared optimum): {seconds:.1f} s (target <= {TARGET_S:g} s: "
          f"{'met' if seconds <= TARGET_S else 'missed'}); the shared optimum alone {shared_seconds:.1f} s")
    if anchor is not None:
        print(f"anchor, the optimum alone, each target by itself (CBC): {anchor_seconds:.1f} s; "
              f"ratio anchor / shared {anchor_seconds / shared_seconds:.1f}x; proven optima "
              f"{'agree' if same else 'DIFFER'}")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
