"""The paper's comparison figure: one case, the same initial view, GMC, MA-SCVP, Ours and the exact
optimum at a matched view count (Ours' count: its initial view and warm-up NBV included).

* **Ours**: :func:`tpvp.simulate.single_plant.run_case`;
* **GMC**: the sequential NBV curve (:func:`tpvp.experiments.baselines.nbv_curve`) stopped at the
  same number of views, moves in execution order with the obstacle radius known at each move;
* **MA-SCVP**: the learned one-shot view set after one PC-NBV view
  (:func:`tpvp.learning.methods.learned_one_shot`), with as many views as it predicts (as in the
  paper, where it predicts as many as Ours); it knows the 32 hemisphere views only;
* **optimum**: the most oracle voxels any set of that many views (initial view included) sees
  (:func:`tpvp.setcover.maxcover.max_coverage` on the ground truth), in its shortest open path from
  the initial view.

:func:`write_comparison` draws the three side by side (views and path; covered and missed voxels
seen from below) and saves a rerun recording with every plan's cameras and path.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import sparse

from tpvp.config import PlantConfig
from tpvp.config_loading import with_overrides
from tpvp.experiments.baselines import nbv_curve
from tpvp.simulate.single_plant import Scene, run_case
from tpvp.learning.methods import learned_one_shot
from tpvp.learning.dataset import VIEWS as LEARNED_VIEWS
from tpvp.path.local import local_path_lengths, local_path_points, obstacle_radius
from tpvp.path.tsp import shortest_open_path
from tpvp.setcover.maxcover import max_coverage
from tpvp.visibility import coverage_ratio, covered_voxels
from tpvp.io import atomic_write_text
from tpvp.io.publish import staged_folder
from tpvp.viz.experiments import plot_method_comparison
from tpvp.viz.interactive import scene_3d
from tpvp.viz.recording import write_recording


@dataclass(frozen=True, eq=False)
class ComparedPlan:
    """One method's executed views on one case."""

    method: str
    order: list  # view indices in execution order, the initial view first
    coverage: float  # of the oracle set
    path_length: float  # planning frame, m
    polyline: np.ndarray  # (n, 3) the path's points
    covered: np.ndarray  # (grid voxels,) bool: seen by some executed view
    note: str = ""


def _polyline(positions, radii, centre) -> np.ndarray:
    """Local paths between consecutive positions, each with its own obstacle radius."""
    if len(positions) < 2:
        return np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    return np.concatenate([local_path_points(a, b, centre, r) for a, b, r in zip(positions[:-1], positions[1:], radii)])


def _plan(scene: Scene, method: str, order, path_length, radii, note="") -> ComparedPlan:
    covered = np.zeros(scene.grid.size, dtype=bool)
    covered[covered_voxels(scene.truth_visibility, order)] = True
    return ComparedPlan(method, [int(v) for v in order],
                        coverage_ratio(covered_voxels(scene.truth_visibility, order), scene.oracle),
                        float(path_length), _polyline(scene.view_space.positions[order], radii, np.zeros(3)),
                        covered, note)


def compare_methods(scene: Scene, config: PlantConfig, views: int | None = None) -> list[ComparedPlan]:
    """GMC, MA-SCVP (where the view space holds its 32 views), Ours and the exact optimum on one
    case with ``views`` views each (default: as many as Ours uses; MA-SCVP: as many as it predicts)."""
    centre = np.zeros(3)
    ours = run_case(scene, config)
    order = ours.order
    views = int(views or len(order))
    radius = ours.obstacle[1]
    plans = [_plan(scene, "ours", order, ours.path_length, [radius] * (len(order) - 1),
                   f"{len(ours.executed_views)} executed + {len(ours.planned_views)} planned")]

    curve = nbv_curve(scene, config, max_views=views)
    plans.insert(0, _plan(scene, "gmc", curve["view"].tolist(), curve["path_length"].iloc[-1],
                          curve["radius"].iloc[1:].tolist(), "sequential NBV, execution order"))
    if len(scene.view_space) >= LEARNED_VIEWS:
        learned = learned_one_shot(scene, with_overrides(config, {"nbv.method": "pc-nbv", "nbv.warm_up_views": 1}))
        order = [*learned["executed_views"], *learned["planned_order"]]
        plans.insert(1, _plan(scene, "ma-scvp", order, learned["path_length_m"],
                              [learned["obstacle_radius"]] * (len(order) - 1),
                              f"1 PC-NBV view + {learned['planned_views']} predicted"))

    initial = scene.view_space.view_index(config.initial_view)
    oracle = np.asarray(scene.oracle)
    visibility = sparse.csr_matrix(scene.truth_visibility)[:, oracle]
    best = max_coverage(visibility, max(views - 1, 1), executed=[initial], config=config.selection.set_cover)
    stops = [initial, *best.selected.tolist()]
    radius = obstacle_radius(scene.grid.centres[oracle], centre)
    tsp = shortest_open_path(local_path_lengths(scene.view_space.positions[stops], centre, radius), start=0,
                             config=config.path)
    order = [stops[i] for i in tsp.order]
    proof = "proven optimal" if best.optimal else f"gap {100 * best.gap:.1f} %"
    plans.append(_plan(scene, "optimum", order, tsp.length, [radius] * (len(order) - 1),
                       f"max coverage with perfect knowledge, {proof}"))
    return plans


def write_comparison(folder, scene: Scene, config: PlantConfig, views: int | None = None, title: str = "") -> dict:
    """The comparison figure (PNG), a table of the plans (CSV) and a rerun recording, written
    into ``folder`` as one published folder."""
    with staged_folder(folder) as stage:
        written = write_comparison_files(stage.folder, scene, config, views, title)
    folder = Path(folder)
    return {**written, "figure": folder / "comparison.png", "recording": folder / "comparison.rrd"}


def write_comparison_files(folder, scene: Scene, config: PlantConfig, views: int | None = None,
                           title: str = "") -> dict:
    """:func:`write_comparison` into a folder being staged by the caller (atomic files, no folder
    publication of its own)."""
    import pandas as pd

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    plans = compare_methods(scene, config, views)
    space = scene.view_space
    oracle = np.asarray(scene.oracle)
    table = pd.DataFrame([{"method": p.method, "views": len(p.order), "coverage": p.coverage,
                           "missed_voxels": int(np.count_nonzero(~p.covered[oracle])), "path_length_m": p.path_length,
                           "order": " ".join(map(str, p.order)), "note": p.note} for p in plans])
    atomic_write_text(folder / "comparison.csv", table.to_csv(index=False))
    figure = plot_method_comparison(folder / "comparison.png", scene, plans, title)
    colours = {"gmc": (40, 90, 220), "ma-scvp": (230, 150, 20), "ours": (220, 40, 40), "optimum": (30, 30, 30)}
    recording = write_recording(
        folder / "comparison.rrd", clouds={"current_truth": (scene.current, (120, 120, 120))},
        cameras={f"{p.method}_views": (space.positions[p.order], space.look_ats[p.order]) for p in plans},
        paths={f"{p.method}_path": p.polyline for p in plans},
        path_colours={f"{p.method}_path": colours[p.method] for p in plans})
    return {"table": table, "figure": figure, "recording": recording, "plans": plans}


def comparison_3d(scene: Scene, plan: ComparedPlan, title: str = ""):
    """An interactive (plotly) view of one compared plan: the plant voxels it covered (blue) and
    the observable ones it missed (red), its views in execution order and its path."""
    plant = scene.grid.countable
    observable = np.zeros(scene.grid.size, bool)
    observable[scene.oracle] = True
    centres, space = scene.grid.centres, scene.view_space
    return scene_3d({"covered voxels": (centres[plant & plan.covered], "royalblue"),
                     "missed voxels (observable)": (centres[plant & observable & ~plan.covered], "red")},
                    candidates=space.positions, executed=space.positions[plan.order[:1]],
                    selected=space.positions[plan.order[1:]], look_ats=space.look_ats[plan.order[1:]],
                    path_polyline=plan.polyline,
                    title=title or f"{plan.method}: {len(plan.order)} views, {100 * plan.coverage:.2f} % coverage")
