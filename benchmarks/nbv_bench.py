"""Speed of one geometric NBV step (map update + information gain), before/after, in the same process.

Run from the repository root::

    python benchmarks/nbv_bench.py            # 20-view GMC runs (as the baseline's nbv_curve), ~2 minutes
    python benchmarks/nbv_bench.py --quick    # 6 views

Scenes: generated tomato and maize (instance 0 of :func:`tpvp.experiments.plants.generated_instances`),
in the hemisphere (32 views) and sphere (63 views) view spaces, initial view 17, the plant
configuration (``make_config("plant")``). Each run is the GMC baseline's sequence: from the initial
view, choose the NBV, observe it (the ground-truth visibility), integrate it, and so on.

* before (the anchor): the map rebuilt from every view at every step
  (``GeometricNbv(incremental=False)``) and gains walked ray by ray (``information_gain(...,
  reference=True)``);
* after (the default): the map integrates only the new view while its geometry stays (rebuilt when a
  view sees farther from the centre than every earlier one), gains counted by voxel.

A step's seconds cover the map update and the gains of every candidate view (what ``nbv_curve``
times). The choices and gains of both must be identical (checked, not only timed). Kernels are
compiled before timing (``tpvp.pipeline.jit.compile_kernels`` plus a warm-up of the reference walk).
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

try:
    import tpvp  # noqa: F401
except ImportError:  # not installed: run from a checkout
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numba
import pandas as pd

from tpvp.config_loading import make_config
from tpvp.experiments import plants
from tpvp.simulate.single_plant import build_scene
from tpvp.pipeline.jit import compile_kernels
from tpvp.nbv.information_gain import information_gain
from tpvp.nbv.occupancy import OccupancyMap
from tpvp.nbv.information_gain import next_best_view
from tpvp.nbv.methods import GeometricNbv, NbvChoice, NbvContext


class _ReferenceNbv(GeometricNbv):
    """The previous path: rebuild the map after every view, walk every ray for the gains."""

    def __init__(self, context):
        super().__init__(context, incremental=False)

    def next_view(self) -> NbvChoice:
        space, sensor = self.context.view_space, self.context.sensor
        view, gains = next_best_view(self.occupancy, space.positions, space.look_ats, executed=self.executed,
                                     stride=self.context.config.pixel_stride, max_range=sensor.max_range,
                                     intrinsics=sensor.intrinsics, reference=True)
        return NbvChoice(view, gains)


def _scene(species: str, view_space: str):
    config = make_config("plant")
    instance = [i for i in plants.generated_instances() if i.species == species][0]
    case = plants.Case(instance, view_space, 0.0, 17)
    case_config = case.config(config)
    scene = build_scene(*instance.load(), case_config)
    return scene, case_config


def _run(nbv, scene, initial: int, n_views: int):
    """``(views, gains per step, seconds per step)`` of one GMC sequence (the steps after the initial view)."""
    def observation(view):
        return scene.grid.centres[scene.truth_visibility[view].indices]

    nbv.integrate(initial, observation(initial))
    views, gains, seconds = [initial], [], []
    for _ in range(1, min(n_views, len(scene.view_space))):
        start = time.perf_counter()
        choice = nbv.next_view()  # the map update (lazy) and the gains
        seconds.append(time.perf_counter() - start)
        nbv.integrate(choice.view, observation(choice.view))
        views.append(choice.view)
        gains.append(choice.scores)
    return views, gains, np.array(seconds)


def _warm_up_reference():
    m = OccupancyMap.empty(np.zeros(3), 0.05)
    information_gain(m, [[0.3, 0.0, 0.1]], np.zeros(3), stride=32, reference=True)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="6-view runs instead of 20")
    parser.add_argument("--views", type=int, default=None, help="views per run, initial included")
    args = parser.parse_args(argv)
    n_views = args.views or (6 if args.quick else 20)

    t = time.perf_counter()
    compile_kernels()
    _warm_up_reference()
    print(f"kernels ready in {time.perf_counter() - t:.1f} s; numba threads {numba.get_num_threads()}, "
          f"{os.cpu_count()} CPUs, {platform.processor() or platform.machine()}")

    rows, identical = [], True
    for view_space in ("hemisphere", "sphere"):
        for species in ("tomato", "maize"):
            scene, config = _scene(species, view_space)
            context = NbvContext(scene.view_space, np.zeros(3), scene.sensor, config.nbv)
            initial = scene.view_space.view_index(config.initial_view)
            before = _run(_ReferenceNbv(context), scene, initial, n_views)
            after = _run(GeometricNbv(context), scene, initial, n_views)
            same = before[0] == after[0] and all(
                np.array_equal(a, b) and a.dtype == b.dtype for a, b in zip(before[1], after[1]))
            identical &= same
            rows.append({
                "scene": f"{species} {view_space}",
                "views": len(scene.view_space),
                "steps": len(after[2]),
                "before s/step": before[2].mean(),
                "after s/step": after[2].mean(),
                "ratio": before[2].mean() / after[2].mean(),
                "before step 2": before[2][0],
                "after step 2": after[2][0],
                "after max": after[2].max(),
                "before total": before[2].sum(),
                "after total": after[2].sum(),
                "identical": same,
            })
            print(f"  {species} {view_space}: views {after[0]}", flush=True)
    table = pd.DataFrame(rows)
    with pd.option_context("display.width", 200, "display.float_format", "{:.3f}".format):
        print(table.to_string(index=False))
    print("choices and gains identical:", identical)
    return 0 if identical else 1


if __name__ == "__main__":
    sys.exit(main())
