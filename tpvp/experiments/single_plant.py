"""One individual-plant case of the paper, end to end in the simulator.

scan -> coarse reconstruction (initial view + warm-up NBV) -> registration of the previous session
-> inflation -> visibility on the planning surface -> view selection -> open TSP -> execution on
the current session's ground truth. Every stage's method is chosen by name in the configuration
(:class:`tpvp.config.PlantConfig`); this module only calls them in order.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import sparse

from tpvp.config import PlantConfig
from tpvp.inflation import inflate
from tpvp.inflation.weights import surface_area, surface_classes, surface_weights
from tpvp.nbv.warm_up import warm_up
from tpvp.path.local import predicted_size
from tpvp.path.route import path_through
from tpvp.registration.methods import register
from tpvp.scene import voxels
from tpvp.scene.grid import build_grid
from tpvp.scene.simulator import Scene, build_scene, observation  # noqa: F401 (callers build the case's scene here)
from tpvp.setcover.methods import SelectionProblem, select_views
from tpvp.visibility import coverage_ratio, covered_voxels, visibility_matrix


@dataclass(frozen=True, eq=False)
class CaseResult:
    executed_views: list  # initial view and warm-up NBVs, in order
    planned_views: list  # selected views in execution order (after the last warm-up view)
    coverage: float
    coverage_warm_up: float
    n_views: int  # warm-up views included, as in the paper
    path_length: float  # planning frame (m)
    chamfer_before: float  # transferred model vs coarse reconstruction (m, planning frame)
    chamfer_after: float
    selection: object  # tpvp.setcover.methods.Selection
    tsp: object
    timings: dict
    clouds: dict  # coarse, previous, warped, inflation, planning (for figures and recordings)
    obstacle: tuple  # (centre, radius) of the path's collision sphere
    warnings: list = field(default_factory=list)  # plausibility warnings in the user's terms
    planning_target: float = 1.0  # fraction of the planning surface the selection had to see

    @property
    def order(self) -> list:
        """Every executed view in execution order: the initial view, the warm-up views, the planned ones."""
        return list(self.executed_views) + list(self.planned_views)

    @property
    def set_cover(self):
        """The set-cover solver's own result (bound, gap, dropped voxels), when that method ran."""
        return self.selection.details

    def summary(self) -> dict:
        details = self.selection.details
        solver = {}
        if details is not None and hasattr(details, "objective"):
            solver = {"set_cover_objective": details.objective, "set_cover_bound": details.bound,
                      "set_cover_gap": details.gap, "set_cover_optimal": details.optimal}
            if hasattr(details, "n_dropped_infeasible"):  # full set cover
                solver["set_cover_dropped_voxels"] = details.n_dropped_infeasible
            else:  # partial set cover (a coverage target below 1)
                solver.update(set_cover_required_weight=details.required_weight,
                              set_cover_covered_weight=details.covered_weight,
                              set_cover_achievable_weight=details.achievable_weight)
        return {
            "views": self.n_views, "coverage": self.coverage, "path_length_m": self.path_length,
            "warm_up_views": len(self.executed_views), "planned_views": len(self.planned_views),
            "planning_target": self.planning_target,
            "coverage_after_warm_up": self.coverage_warm_up,
            "chamfer_before_mm": 1e3 * self.chamfer_before, "chamfer_after_mm": 1e3 * self.chamfer_after,
            "selection_optimal": bool(self.selection.optimal), "selection_status": self.selection.status,
            **solver, "tsp_optimal": self.tsp.optimal, "tsp_method": self.tsp.method,
            "warnings": " | ".join(self.warnings),
            **{f"seconds_{k}": v for k, v in self.timings.items()},
        }


def added_coverage(scene, executed) -> np.ndarray:
    """Per view: the oracle voxels it sees that none of ``executed`` sees (``(V,)`` int)."""
    truth = sparse.csr_matrix(scene.truth_visibility)
    new = np.zeros(truth.shape[1], dtype=bool)
    new[scene.oracle] = True
    for v in executed:
        new[truth.indices[truth.indptr[v]:truth.indptr[v + 1]]] = False
    return np.asarray(truth @ new.astype(np.int64)).ravel()


def rank_of(added: np.ndarray, executed, view: int) -> int:
    """1 + the number of non-executed candidates that add strictly more than ``view``."""
    candidates = np.ones(len(added), dtype=bool)
    candidates[list(executed)] = False
    return 1 + int((added[candidates] > added[view]).sum())


@dataclass(frozen=True, eq=False)
class Transfer:
    """What the robot knows before planning: the executed views (initial + warm-up NBVs), their
    observations (the coarse reconstruction) and the previous session aligned onto it."""

    nbv: object  # the NBV method object, holding the executed views' state
    executed: list
    coarse: np.ndarray  # observed points, duplicates kept (as the reference feeds registration)
    alignment: object  # tpvp.registration.methods.Alignment
    timings: dict  # warm_up, registration (s)
    warnings: list


def transfer(scene: Scene, config: PlantConfig = PlantConfig(), progress=None, nbv=None) -> Transfer:
    """Initial view, warm-up NBVs and registration of the previous session onto what they saw.
    ``nbv``: the NBV method holding views already executed (a real session's captures); then no
    view is rendered and ``scene`` needs only its view space, sensor, previous session and names."""
    say = progress or (lambda stage: None)
    timings = {}
    t = time.perf_counter()
    say("warm-up NBV")
    nbv = nbv or warm_up(scene, config)
    coarse = np.concatenate(nbv.observations)
    timings["warm_up"] = time.perf_counter() - t

    t = time.perf_counter()
    say("registration")
    alignment = register(scene.previous, coarse, config.registration, name=scene.names[0])
    timings["registration"] = time.perf_counter() - t
    return Transfer(nbv, list(nbv.executed), coarse, alignment, timings,
                    _registration_warnings(scene, alignment, config))


def planning_visibility(scene: Scene, planning_cloud, resolution: float):
    """The planning grid of ``planning_cloud`` voxelised at ``resolution`` and what each candidate
    view sees of it (ray casting): ``(grid, (views x planning voxels) matrix)``."""
    grid = build_grid(voxels.voxelise(planning_cloud, resolution), resolution)
    space = scene.view_space
    return grid, visibility_matrix(grid, space.positions, space.look_ats, scene.sensor)


def run_case(scene: Scene, config: PlantConfig = PlantConfig(), progress=None,
             transferred: Transfer | None = None, surface: PlanningSurface | None = None) -> CaseResult:
    """Warm-up, transfer, plan and execute one case; ``progress(stage)`` is called per stage.
    ``transferred``: the :func:`transfer` of this scene and configuration when already computed
    (methods that differ only after registration share it); ``surface``: likewise its
    :func:`planning_surface` (plans that differ only in the selection share it)."""
    result = plan_case(scene, config, progress, transferred, surface)
    executed, planned = result.executed_views, result.planned_views
    return replace(result, coverage=coverage_ratio(covered_voxels(scene.truth_visibility, executed + planned),
                                                   scene.oracle),
                   coverage_warm_up=coverage_ratio(covered_voxels(scene.truth_visibility, executed), scene.oracle))


@dataclass(frozen=True, eq=False)
class PlanningSurface:
    """The planning surface of a case and what the candidate views see of it: the inflation's
    result (P~ u Q u I), the planning grid, the (views x planning voxels) visibility, the class and
    the area of each planning voxel (:mod:`tpvp.inflation.weights`) and the stage timings."""

    inflated: object  # tpvp.inflation.InflationResult
    grid: object  # tpvp.scene.grid.OccupancyGrid
    visibility: object
    classes: np.ndarray | None  # None unless config.surface_weights.enabled
    area: np.ndarray | None
    timings: dict


def planning_surface(scene: Scene, config: PlantConfig, transferred: Transfer, progress=None) -> PlanningSurface:
    """Inflation, the planning grid with its voxel classes, and visibility (ray casting)."""
    say = progress or (lambda stage: None)
    timings = {}
    centre = np.zeros(3)
    t = time.perf_counter()
    say("inflation")
    coarse, warped = transferred.coarse, transferred.alignment.warped
    inflated = inflate(warped, coarse, centre, predicted_size(coarse, centre), config.inflation)
    timings["inflation"] = time.perf_counter() - t

    t = time.perf_counter()
    say("visibility")
    resolution = config.selection.cover_resolution
    grid, visibility = planning_visibility(scene, inflated.planning, resolution)
    classes = area = None  # only a weighted coverage target reads them
    if config.surface_weights.enabled:
        classes = surface_classes(grid.keys, resolution, warped, coarse, config.surface_weights.near_voxels * resolution)
        area = surface_area(grid.keys, resolution, inflated.planning) if config.surface_weights.area else None
    timings["visibility"] = time.perf_counter() - t
    return PlanningSurface(inflated, grid, visibility, classes, area, timings)


def selection_problem(scene: Scene, config: PlantConfig, transferred: Transfer,
                      surface: PlanningSurface) -> SelectionProblem:
    """The view selection on ``surface``: the executed views, the planning target of the coverage
    target and, below a target of 1, the voxels' class weights (``config.surface_weights``)."""
    selection = config.selection
    weights = None
    if selection.coverage_target < 1.0 and config.surface_weights.enabled:
        weights = surface_weights(surface.classes, config.surface_weights, surface.area)
    return SelectionProblem(surface.visibility, tuple(transferred.executed), scene.view_space,
                            surface.grid.centres, selection.planning_target(config.view_space),
                            voxel_weights=weights, nbv=transferred.nbv)


def plan_case(scene, config: PlantConfig = PlantConfig(), progress=None,
              transferred: Transfer | None = None, surface: PlanningSurface | None = None) -> CaseResult:
    """Warm-up, transfer and plan, without executing the plan: the coverages are NaN (a real
    session has no ground truth to measure them on). ``surface``: the :func:`planning_surface` of
    this scene, transfer and configuration when already computed (plans that differ only in the
    selection share it)."""
    say = progress or (lambda stage: None)
    space = scene.view_space
    centre = np.zeros(3)
    transferred = transferred or transfer(scene, config, progress)
    executed, coarse, alignment = transferred.executed, transferred.coarse, transferred.alignment
    timings = dict(transferred.timings)
    warnings = list(transferred.warnings)

    surface = surface or planning_surface(scene, config, transferred, progress)
    timings.update(surface.timings)

    t = time.perf_counter()
    say("view selection")
    problem = selection_problem(scene, config, transferred, surface)
    selection = select_views(problem, config.selection)
    timings["selection"] = time.perf_counter() - t

    t = time.perf_counter()
    say("path")
    planned, path_length, tsp, radius = path_through(space, executed, selection.selected, coarse, config)
    timings["path"] = time.perf_counter() - t
    timings["planning"] = sum(timings[k] for k in ("inflation", "visibility", "selection", "path"))

    return CaseResult(
        executed_views=executed, planned_views=planned,
        coverage=float("nan"), coverage_warm_up=float("nan"), n_views=len(executed) + len(planned), path_length=path_length,
        chamfer_before=alignment.chamfer_before, chamfer_after=alignment.chamfer_after,
        selection=selection, tsp=tsp, timings=timings,
        clouds={"coarse": np.unique(coarse, axis=0), "previous": scene.previous,
                "warped": alignment.warped, "inflation": surface.inflated.inflation,
                "planning": surface.inflated.planning},
        obstacle=(centre, radius), warnings=warnings, planning_target=problem.planning_target,
    )


def _registration_warnings(scene: Scene, alignment, config: PlantConfig) -> list:
    """A registration that ends far from the coarse scan for the plant's size means the two scans
    are hardly two sessions of one plant; said in the scans' own units."""
    size = config.scene.largest_side
    fraction = alignment.chamfer_after / size
    if fraction <= config.registration.warn_chamfer_fraction:
        return []
    # Scan metres, in mm for a plant under a metre (as read with --units mm or auto), else in m
    # (as read with --units m: the user sees the numbers of the files).
    per_scan, unit = 1.0 / scene.scan_scale, "m"
    if size * per_scan < 1.0:
        per_scan, unit = 1e3 * per_scan, "mm"
    return [f"registration of {scene.names[0]} onto the coarse scan of {scene.names[1]} ends at "
            f"{alignment.chamfer_after * per_scan:.3g} {unit} Chamfer ({100 * fraction:.1f} % of the plant's "
            f"{size * per_scan:.3g} {unit}; a matching pair of sessions ends below "
            f"{100 * config.registration.warn_chamfer_fraction:g} %): are these two sessions of the same "
            f"plant? The plan relies on the aligned previous session"]
