"""How good is the warm-up NBV? Rank of the chosen view by the coverage it truly adds.

Run from the repository root::

    python benchmarks/nbv_rank.py                      # the protocol: 2 x 42 cases, every method
    python benchmarks/nbv_rank.py --quick              # a few cases
    python benchmarks/nbv_rank.py --seeds 10 11 12 --no-bundled   # held-out generated plants
    python benchmarks/nbv_rank.py --methods geometric prior --output ranks.csv

Cases: the individual-plant protocol (:func:`tpvp.experiments.plants.case_list`): generated tomato
and maize pairs (``--seeds``, default 0 1 2) plus the bundled real pair, rotations 0 and 45 deg,
initial views 17, 8 and 21, in the hemisphere (32 views) and sphere (63 views) view spaces; the
paper configuration (``make_config("plant")``). Per case the scene is built
(:func:`tpvp.simulate.single_plant.build_scene`), the initial view is executed (its ground-truth
observation integrated) and every NBV method (``--methods``, default ``geometric`` and ``prior``;
names of :data:`tpvp.nbv.methods.NBV_METHODS`) picks the next view from the same
:class:`~tpvp.nbv.methods.NbvContext` as :func:`~tpvp.simulate.single_plant.transfer` gives it
(the previous session as ``prior``).

Score: the TRUE added coverage of every non-executed candidate, the oracle voxels it sees in
``scene.truth_visibility`` that the initial view does not; the chosen view's rank is
``1 + #candidates with strictly more`` (1 = a best view; 31 candidates in the hemisphere, 62 in
the sphere). Also reported: the chosen view's added coverage as a fraction of the best one's.
Seconds: the ``next_view()`` call (``s_mean``, ``s_max``; lazily built state such as the prior
method's visibility matrix is built there), and the method's whole cost for the case, construction
and integration of the initial view included (``s_total_max``). Kernels are compiled before timing.
"""

from __future__ import annotations

import argparse
import os
import platform
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

from tpvp.config_loading import make_config
from tpvp.experiments import plants
from tpvp.simulate.single_plant import added_coverage, build_scene, rank_of
from tpvp.pipeline.jit import compile_kernels
from tpvp.nbv.methods import NBV_METHODS, NbvContext, make_nbv


def run_cases(cases, methods, base) -> pd.DataFrame:
    rows = []
    scene_key, scene = None, None
    for n, case in enumerate(cases, 1):
        config = case.config(base)
        key = (case.instance, case.view_space, case.rotation_deg)
        if key != scene_key:
            t = time.perf_counter()
            scene_config = replace(config, initial_view=0)
            previous, current = case.instance.load()
            scene = build_scene(previous, current, scene_config)
            scene_key = key
            print(f"[{n}/{len(cases)}] scene {case.instance.name} {case.view_space} rot {case.rotation_deg:g}: "
                  f"{time.perf_counter() - t:.1f} s", flush=True)
        space = scene.view_space
        initial = space.view_index(config.initial_view)
        observed = scene.grid.centres[scene.truth_visibility[initial].indices]
        added = added_coverage(scene, [initial])
        best = int(np.delete(added, initial).max())
        line = []
        for method in methods:
            t0 = time.perf_counter()
            nbv = make_nbv(NbvContext(space, np.zeros(3), scene.sensor, replace(config.nbv, method=method),
                                      prior=scene.previous))
            nbv.integrate(initial, observed)
            t = time.perf_counter()
            choice = nbv.next_view()
            seconds = time.perf_counter() - t
            total = time.perf_counter() - t0
            rank = rank_of(added, [initial], choice.view)
            rows.append({**case.labels(), "method": method, "view": choice.view, "rank": rank,
                         "candidates": len(space) - 1, "added": int(added[choice.view]), "best_added": best,
                         "fraction_of_best": added[choice.view] / best if best else np.nan,
                         "seconds": seconds, "seconds_total": total})
            line.append(f"{method} {choice.view}->#{rank} ({seconds:.2f} s)")
        print(f"    initial {initial}: " + ", ".join(line), flush=True)
    return pd.DataFrame(rows)


def summary(raw: pd.DataFrame) -> pd.DataFrame:
    """Per view space and method: every case, then the generated and the bundled ones apart."""
    out = []
    for space, in_space in raw.groupby("view_space", sort=False):
        subsets = [("all", in_space)]
        if in_space["source"].nunique() > 1:
            subsets += [(source, part) for source, part in in_space.groupby("source", sort=False)]
        for subset, part in subsets:
            for method, g in part.groupby("method", sort=False):
                r = g["rank"].to_numpy()
                row = {"view_space": space, "cases": f"{subset} ({len(r)})", "method": method}
                for k in (1, 3, 5, 10):
                    row[f"top{k}"] = float(np.mean(r <= k))
                row.update(median=float(np.median(r)), max=int(r.max()),
                           frac_best=float(g["fraction_of_best"].mean()))
                for view, gv in g.groupby("initial_view"):
                    row[f"med@{view}"] = float(np.median(gv["rank"]))
                    row[f"max@{view}"] = int(gv["rank"].max())
                row.update(s_mean=float(g["seconds"].mean()), s_max=float(g["seconds"].max()),
                           s_total_max=float(g["seconds_total"].max()))
                out.append(row)
    return pd.DataFrame(out)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true",
                        help="seed 0 tomato and maize, rotation 0, the three initial views")
    parser.add_argument("--seeds", type=int, nargs="+", default=list(plants.GENERATED_SEEDS),
                        help="seeds of the generated pairs (default 0 1 2)")
    parser.add_argument("--no-bundled", action="store_true", help="leave out the bundled real pair")
    parser.add_argument("--view-spaces", nargs="+", default=list(plants.VIEW_SPACES))
    parser.add_argument("--methods", nargs="+", default=["geometric", "prior"],
                        help=f"NBV methods (registered: {', '.join(NBV_METHODS.names())})")
    parser.add_argument("--output", help="write one row per (case, method) to this CSV")
    args = parser.parse_args(argv)

    for method in args.methods:
        NBV_METHODS.get(method)  # an unknown name fails here, before any work
    instances = plants.generated_instances(seeds=(args.seeds[0],) if args.quick else tuple(args.seeds))
    if not args.no_bundled and not args.quick:
        instances.append(plants.bundled_instance())
    rotations = plants.ROTATIONS[:1] if args.quick else plants.ROTATIONS
    cases = plants.case_list(instances, tuple(args.view_spaces), rotations, plants.INITIAL_VIEWS)

    t = time.perf_counter()
    compile_kernels()
    _compile_methods(args.methods)
    print(f"kernels ready in {time.perf_counter() - t:.1f} s; numba threads {numba.get_num_threads()}, "
          f"{os.cpu_count()} CPUs, {platform.processor() or platform.machine()}; {len(cases)} cases", flush=True)

    raw = run_cases(cases, args.methods, make_config("plant"))
    if args.output:
        raw.to_csv(args.output, index=False)
        print(f"rows written to {args.output}")
    table = summary(raw)
    with pd.option_context("display.width", 250, "display.max_columns", 40, "display.float_format", "{:.3g}".format):
        print(table.to_string(index=False))
    for (space, method), g in raw.groupby(["view_space", "method"], sort=False):
        counts = np.bincount(g["rank"], minlength=g["candidates"].max() + 1)[1:]
        print(f"rank histogram {space} {method}: " +
              " ".join(f"{k + 1}:{c}" for k, c in enumerate(counts) if c))
    return 0


def _compile_methods(methods) -> None:
    """One untimed call of every method on a tiny scene, so that its kernels are compiled."""
    from tpvp.nbv.config import NbvConfig
    from tpvp.sensor.sensor import SensorConfig
    from tpvp.viewspace.space import get_view_space

    space = get_view_space("hemisphere")
    rng = np.random.default_rng(0)
    prior = rng.normal(scale=0.03, size=(300, 3))
    for method in methods:
        nbv = make_nbv(NbvContext(space, np.zeros(3), SensorConfig(), NbvConfig(method=method), prior=prior))
        nbv.integrate(17, prior[prior[:, 0] > 0.01])
        nbv.next_view()


if __name__ == "__main__":
    raise SystemExit(main())
