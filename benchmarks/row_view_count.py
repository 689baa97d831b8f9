"""Why Ours selects the views it does in greenhouse rows (issue 27.2): the set-cover instance per
case, reference and covering voxel, measured.

For each case (generated rows, ``--references``) and covering voxel, with the paper-row
configuration: the planning surface (points, planning voxels, points per voxel), what the passive
sweep and the candidates see of it (coverable voxels, voxels left to cover after the sweep,
candidates per voxel, voxels only one candidate sees, the candidates that are the only one for some
voxel), the look-at targets (count, candidates per target) and the selected views. The same set
cover is also solved with the authors' own PriorTemporal look-ats of the same date (``gap_1``, made
on the real rows) in place of our transfer targets, and on the aligned previous session alone
(no inflation, no passive reconstruction), to separate what the views follow; and restricted to
the voxels within one or two covering voxels of the row's front surface (the most aisle-ward voxel
of each column), to measure how the depth of the canopy the plan must see sets the view count.

Usage:
    python benchmarks/row_view_count.py [--references handheld candidates complete]
        [--resolutions 0.10 0.05 0.04 0.03] [--rooms room1 room4] [--pairs 0 1 2 3] [--cache DIR]
Writes benchmarks/results/row_view_count.md (with this command) and prints the tables.
"""

from __future__ import annotations

import argparse
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pandas as pd

from tpvp.config_loading import make_config
from tpvp.simulate.greenhouse import build_row_scene, row_transfer
from tpvp.pipeline.plan import inflated, row_view_space
from tpvp.pipeline.surface import planning_visibility
from tpvp.simulate.row_cases import RowCase
from tpvp.io import atomic_write_text
from tpvp.pipeline.jit import compile_kernels
from tpvp.metrics.views import forced_views, views_per_voxel
from tpvp.scene import voxels
from tpvp.setcover.methods import SelectionProblem, select_views
from tpvp.viewspace.priors import candidate_views
from results_file import write_results

RESULTS = Path(__file__).resolve().parent / "results"


def depth_behind_front(box, aisle_centre, centres, resolution: float) -> np.ndarray:
    """Per voxel centre: how far (m) it lies behind the row's front surface, the most aisle-ward
    voxel of its (along, up) column in the box frame."""
    local = box.to_local(centres)
    aisle = np.sign(box.to_local(aisle_centre)[1]) or 1.0
    across = aisle * local[:, 1]
    _, column = np.unique(np.round(local[:, [0, 2]] / resolution).astype(np.int64), axis=0, return_inverse=True)
    front = np.full(column.max() + 1, -np.inf)
    np.maximum.at(front, column.ravel(), across)
    return front[column.ravel()] - across


@dataclass(frozen=True)
class _Visibility:
    """The passive views, then the candidates, on a planning surface at one covering voxel."""

    grid: object
    view_space: object
    matrix: object
    n_passive: int
    resolution: float

    @property
    def planning_voxels(self) -> int:
        return self.grid.size

    def problem(self, coverage_target: float) -> SelectionProblem:
        return SelectionProblem(self.matrix, tuple(range(self.n_passive)), self.view_space, self.grid.centres,
                                coverage_target)


def _visibility(room, candidates, points, resolution: float, sensor) -> _Visibility:
    space = row_view_space(room, candidates, sensor)
    grid, matrix = planning_visibility(points, resolution, space.positions, space.look_ats, sensor)
    return _Visibility(grid, space, matrix, len(room.initial_positions), resolution)


def _instance(visibility, selection_config, depth) -> dict:
    """The set-cover instance of one case at one covering voxel, and the views it takes."""
    passive = np.zeros(visibility.matrix.shape[1], bool)
    passive[visibility.matrix[:visibility.n_passive].indices] = True
    candidates = visibility.matrix[visibility.n_passive:]
    per_voxel = views_per_voxel(candidates)
    coverable = passive | (per_voxel > 0)
    left = ~passive & (per_voxel > 0)
    forced = forced_views(candidates, np.flatnonzero(left))
    t = time.perf_counter()
    selection = select_views(visibility.problem(1.0), selection_config)
    seconds = time.perf_counter() - t
    # The same cover restricted to the front layer(s) of the planning surface: how deep the
    # canopy the plan must see sets the view count.
    step = visibility.resolution
    shallow = {}
    for layers in (1, 2):
        keep = np.flatnonzero(depth < (layers - 0.5) * step)
        restricted = replace(visibility, matrix=visibility.matrix[:, keep].tocsr())
        shallow[f"selected_front_{layers}_layers"] = len(select_views(restricted.problem(1.0), selection_config).selected)
    rare = left & (per_voxel == 1)
    return {"planning_voxels": visibility.planning_voxels, "coverable": int(coverable.sum()),
            "passive_sees": int(passive.sum()), "left_to_cover": int(left.sum()),
            "candidates_per_voxel": float(per_voxel[left].mean()) if left.any() else np.nan,
            "voxels_one_candidate": int((left & (per_voxel == 1)).sum()), "forced_views": len(forced),
            "voxels_per_candidate": float(np.diff(candidates.indptr).mean()),
            "one_candidate_behind_front": float((depth[rare] >= 0.5 * step).mean()) if rare.any() else np.nan,
            "selected": len(selection.selected), **shallow, "optimal": bool(selection.optimal),
            "seconds_selection": seconds}


def measure_case(room: str, pair: int, reference: str, resolutions, cache=None) -> list[dict]:
    compile_kernels()
    case = RowCase(room, pair, reference=reference)
    config = case.config(make_config("row"))
    scene = build_row_scene(*case.load(), config, date=case.date, cache_dir=cache)
    transferred = row_transfer(scene, config)
    inflation = inflated(scene.known, config, transferred)
    context = scene.known.prior_context(config.inflation.step, transferred.alignment.warped, inflation.inflation)
    ours = candidate_views("transfer", context, config.targets, config.seed)
    authors = candidate_views("authors-transfer", context, config.targets, config.seed)
    surfaces = {"planning surface": inflation.planning, "aligned previous only": transferred.alignment.warped}
    rows = []
    for resolution in resolutions:
        for (candidates_name, candidates) in (("ours", ours), ("authors' PriorTemporal", authors)):
            for surface_name, points in surfaces.items():
                if candidates_name != "ours" and surface_name != "planning surface":
                    continue
                visibility = _visibility(scene.room, candidates, points, resolution, config.sensor)
                occupied = len(voxels.voxelise(points, resolution))
                targets = len(np.unique(candidates.target_ids)) if len(candidates.target_ids) else 0
                rows.append({"room": room, "pair": pair, "reference": reference, "cover_cm": round(100 * resolution),
                             "candidates": candidates_name, "surface": surface_name, "points": len(points),
                             "points_per_voxel": len(points) / max(occupied, 1), "targets": targets,
                             "views": len(candidates), "views_per_target": len(candidates) / max(targets, 1),
                             **_instance(visibility, config.selection,
                                         depth_behind_front(scene.room.plant_box, scene.room.view_box.center,
                                                            visibility.grid.centres, resolution))})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--references", nargs="+", default=["handheld", "candidates", "complete"])
    parser.add_argument("--resolutions", nargs="+", type=float, default=[0.10, 0.05, 0.04, 0.03])
    parser.add_argument("--rooms", nargs="+", default=["room1", "room4"])
    parser.add_argument("--pairs", nargs="+", type=int, default=[0, 1, 2, 3])
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--cache", default=None, help="oracle cache folder, e.g. the one of `tpvp experiments rows "
                                                     "--cache DIR` (default: $TPVP_CACHE_DIR or ~/.cache/tpvp)")
    parser.add_argument("--output", default=str(RESULTS / "row_view_count.md"))
    args = parser.parse_args()
    jobs = [(room, pair, reference) for reference in args.references for room in args.rooms for pair in args.pairs]
    started = time.perf_counter()
    with ProcessPoolExecutor(args.workers) as pool:
        futures = [pool.submit(measure_case, *job, args.resolutions, args.cache) for job in jobs]
        raw = pd.DataFrame([row for future in futures for row in future.result()])
    keys = ["reference", "candidates", "surface", "cover_cm"]
    columns = ["points_per_voxel", "planning_voxels", "coverable", "passive_sees", "left_to_cover",
               "candidates_per_voxel", "voxels_one_candidate", "one_candidate_behind_front", "forced_views",
               "voxels_per_candidate", "targets", "views_per_target", "selected", "selected_front_1_layers",
               "selected_front_2_layers"]
    table = raw.groupby(keys, sort=False)[columns].mean().reset_index()
    table["views (passive included)"] = table["selected"] + 15
    pd.set_option("display.width", 250)
    print(table.round(2).to_string(index=False))
    print(f"{len(jobs)} cases in {time.perf_counter() - started:.0f} s")
    write_results(args.output, [("set-cover instance, means over the cases", table)],
                  f"{len(jobs)} cases, {time.perf_counter() - started:.0f} s on {args.workers} workers")
    atomic_write_text(Path(args.output).with_suffix(".csv"), raw.to_csv(index=False))


if __name__ == "__main__":
    main()
