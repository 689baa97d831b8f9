"""The planner for one plant: from what the robot knows to a plan.

What it knows (:class:`Known`): the previous session's model, the candidate views and the sensor
in the planning frame, and the views already executed with what they observed (the NBV method's
state: the initial view and the warm-up NBVs). From that: registration of the previous model onto
the coarse reconstruction -> inflation -> visibility of the planning surface (ray casting) -> view
selection -> open TSP around the obstacle sphere. Every stage's method is chosen by name in the
configuration (:class:`tpvp.config.PlantConfig`). The simulator's ground truth is not here: the
simulation (:mod:`tpvp.simulate.single_plant`) executes the warm-up and the plan on it, a real
session (:mod:`tpvp.session.plant`) captures them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import sparse

from tpvp.config import PlantConfig
from tpvp.errors import ConfigError
from tpvp.inflation.inflate import inflate
from tpvp.inflation.weights import surface_area, surface_classes, surface_weights
from tpvp.path.local import predicted_size
from tpvp.path.route import path_through
from tpvp.pipeline.result import PlanResult
from tpvp.pipeline.surface import planning_visibility
from tpvp.pipeline.timing import timed
from tpvp.registration.methods import register
from tpvp.scene.frame import scan_points
from tpvp.scene.organs import CODE, organ_shares, voxel_organs
from tpvp.scene.voxels import contains_keys, dilate_keys
from tpvp.setcover.methods import SelectionProblem, select_views
from tpvp.visibility import covered_voxels, oracle_voxels


#: The stages whose times make ``timings["planning"]`` (after the transfer).
PLANNING_STAGES = ("inflation", "visibility", "selection", "path")

@dataclass(frozen=True, eq=False)
class Known:
    """What the robot knows in the planning frame before it plans: the previous session's model
    (``previous``), the candidate views and the sensor, the planning frame itself
    (``plant_from_scan``: scan metres -> planning frame, scale included) and the supporting table.
    Nothing of today's plant but what the executed views observe (the NBV state given to
    :func:`transfer`)."""

    previous: np.ndarray
    view_space: object  # tpvp.viewspace.ViewSpace
    sensor: object  # SensorConfig in the planning frame
    plant_from_scan: np.ndarray
    table_points: np.ndarray
    names: tuple  # (previous session, today's session) as the user named them
    reduction: dict = field(default_factory=dict)
    previous_organs: np.ndarray | None = None  # organ code of each previous point (tpvp.scene.organs), if labelled

    @property
    def scan_scale(self) -> float:
        """Planning-frame metres per scan metre."""
        return float(np.cbrt(np.linalg.det(self.plant_from_scan[:3, :3])))

    def to_scan(self, points) -> np.ndarray:
        """Planning-frame points in the scan's (world) frame."""
        return scan_points(self.plant_from_scan, points)

    def to_planning(self, points) -> np.ndarray:
        matrix = self.plant_from_scan
        return np.asarray(points, dtype=np.float64) @ matrix[:3, :3].T + matrix[:3, 3]


@dataclass(frozen=True, eq=False)
class CaseResult(PlanResult):
    """A plant's plan (:class:`PlanResult`; ``n_views`` counts the warm-up views, as the paper does)."""

    executed_views: list  # initial view and warm-up NBVs, in order
    planned_views: list  # selected views in execution order (after the last warm-up view)
    coverage_warm_up: float
    chamfer_before: float  # transferred model vs coarse reconstruction (m, planning frame)
    chamfer_after: float
    tsp: object
    clouds: dict  # coarse, previous, warped, inflation, planning (for figures and recordings)
    obstacle: tuple  # (centre, radius) of the path's collision sphere
    planning_target: float = 1.0  # fraction of the planning surface the selection had to see
    replans: tuple = ()  # tpvp.pipeline.replan.Replan rows, in order (selection.replan_after)
    planning_organs: dict = field(default_factory=dict)  # organ -> share of its predicted voxels the plan sees
    organ_coverage: dict = field(default_factory=dict)  # organ -> true coverage (the simulation measures it)

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
            else:  # partial set cover (a coverage target below 1, or one per organ: summed)
                solver.update(set_cover_required_weight=float(np.sum(details.required_weight)),
                              set_cover_covered_weight=float(np.sum(details.covered_weight)),
                              set_cover_achievable_weight=float(np.sum(details.achievable_weight)))
        return {
            **self.headline(),
            "warm_up_views": len(self.executed_views), "planned_views": len(self.planned_views),
            "planning_target": self.planning_target,
            "coverage_after_warm_up": self.coverage_warm_up,
            "chamfer_before_mm": 1e3 * self.chamfer_before, "chamfer_after_mm": 1e3 * self.chamfer_after,
            **self.selection_summary(), **solver, "tsp_optimal": self.tsp.optimal, "tsp_method": self.tsp.method,
            "warnings": " | ".join(self.warnings),
            **{f"coverage_{organ}": value for organ, value in self.organ_coverage.items()},
            **{f"planning_coverage_{organ}": value for organ, value in self.planning_organs.items()},
            **({"replans": len(self.replans), "views_added_by_replanning": sum(r.views_added for r in self.replans),
                "views_dropped_by_replanning": sum(r.views_dropped for r in self.replans)} if self.replans else {}),
            **{f"seconds_{k}": v for k, v in self.timings.items()},
        }


@dataclass(frozen=True, eq=False)
class Transfer:
    """What the robot knows before planning: the executed views (initial + warm-up NBVs), their
    observations (the coarse reconstruction) and the previous session aligned onto it."""

    nbv: object  # the NBV method object, holding the executed views' state
    executed: list
    coarse: np.ndarray  # observed points, duplicates kept (as the reference feeds registration)
    alignment: object  # tpvp.registration.methods.Alignment
    timings: dict  # registration (s); the simulation adds warm_up
    warnings: list


def transfer(known: Known, config: PlantConfig, nbv, progress=None) -> Transfer:
    """Registration of the previous session onto what the executed views saw. ``nbv``: the NBV
    method holding the executed views (the initial view and the warm-up NBVs) and their
    observations, from the simulator or from a real session's captures."""
    say = progress or (lambda stage: None)
    coarse, timings = np.concatenate(nbv.observations), {}
    with timed(timings, "registration", say, "registration"):
        alignment = register(known.previous, coarse, config.registration, name=known.names[0])
    return Transfer(nbv, list(nbv.executed), coarse, alignment, timings, _registration_warnings(known, alignment, config))


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
    organs: np.ndarray | None = None  # organ code of each planning voxel, when the previous model is labelled


def planning_surface(known: Known, config: PlantConfig, transferred: Transfer, progress=None) -> PlanningSurface:
    """Inflation, the planning grid with its voxel classes, and visibility (ray casting)."""
    say = progress or (lambda stage: None)
    timings = {}
    centre = np.zeros(3)
    coarse, warped = transferred.coarse, transferred.alignment.warped
    with timed(timings, "inflation", say, "inflation"):
        inflated = inflate(warped, coarse, centre, predicted_size(coarse, centre), config.inflation)
    with timed(timings, "visibility", say, "visibility"):
        resolution = config.selection.cover_resolution
        space = known.view_space
        grid, visibility = planning_visibility(inflated.planning, resolution, space.positions, space.look_ats,
                                               known.sensor)
        classes = area = None  # only a weighted coverage target reads them
        if config.surface_weights.enabled:
            classes = surface_classes(grid.keys, resolution, warped, coarse,
                                      config.surface_weights.near_voxels * resolution)
            area = surface_area(grid.keys, resolution, inflated.planning) if config.surface_weights.area else None
        # The previous model's labels follow the registration (a method that warps it point by
        # point); voxels of growth or of today's captures alone hold no labelled point: unknown.
        labelled = known.previous_organs is not None and len(known.previous_organs) == len(warped)
        organs = voxel_organs(grid.keys, resolution, warped, known.previous_organs) if labelled else None
    return PlanningSurface(inflated, grid, visibility, classes, area, timings, organs)


def selection_problem(known: Known, config: PlantConfig, transferred: Transfer,
                      surface: PlanningSurface) -> SelectionProblem:
    """The view selection on ``surface``: the executed views, the planning target of the coverage
    target and, below a target of 1, the voxels' class weights (``config.surface_weights``)."""
    selection = config.selection
    weights = None
    if selection.coverage_target < 1.0 and config.surface_weights.enabled:
        weights = surface_weights(surface.classes, config.surface_weights, surface.area)
    target = selection.planning_target(config.view_space)
    targets = selection.organ_target_values()
    groups, shares = (organ_groups(surface.organs, targets, target, known.names[0], surface.grid.keys,
                                   selection.organ_margin_voxels) if targets else (None, None))
    return SelectionProblem(surface.visibility, tuple(transferred.executed), known.view_space,
                            surface.grid.centres, target, voxel_weights=weights, nbv=transferred.nbv,
                            voxel_groups=groups, group_targets=shares)


def organ_groups(organs, targets: dict, planning_target: float, name: str, keys, margin: int):
    """``(group of each planning voxel, each group's share)`` for per-organ targets: one group per
    organ named in ``targets``, one for every other voxel (``planning_target``); a voxel within
    ``margin`` voxels (``selection.organ_margin_voxels``) of a named organ's voxels takes that
    organ's share when it is the stricter. ``keys``: the planning voxels' keys. Targets without
    organ labels are one clear error."""
    if organs is None:
        raise ConfigError(f"organ targets ({', '.join(targets)}) need the previous model's organ labels: {name} "
                          f"has none (give a labelled scan and --labels organ|pheno4d)")
    named = [CODE[organ] for organ in targets]
    shares = np.array([*targets.values(), planning_target])
    groups = np.full(len(organs), len(named), dtype=np.int64)
    for group, code in enumerate(named):
        groups[organs == code] = group
    for group in np.argsort(-shares[:-1], kind="stable"):  # the strictest organ first
        near = contains_keys(dilate_keys(keys[organs == named[group]], margin), keys)
        groups[near & (shares[groups] < shares[group])] = group
    return groups, tuple(shares)


def plan(known: Known, config: PlantConfig, transferred: Transfer, progress=None,
         surface: PlanningSurface | None = None) -> CaseResult:
    """Inflation, visibility, view selection and the path, after :func:`transfer`. The result's
    coverages are NaN: the planner has no ground truth to measure them on (the simulation fills
    them in). ``surface``: the :func:`planning_surface` of this transfer and configuration when
    already computed (plans that differ only in the selection share it)."""
    say = progress or (lambda stage: None)
    space = known.view_space
    centre = np.zeros(3)
    executed, coarse, alignment = transferred.executed, transferred.coarse, transferred.alignment
    timings = dict(transferred.timings)
    warnings = list(transferred.warnings)

    surface = surface or planning_surface(known, config, transferred, progress)
    timings.update(surface.timings)

    with timed(timings, "selection", say, "view selection"):
        problem = selection_problem(known, config, transferred, surface)
        selection = select_views(problem, config.selection)
    with timed(timings, "path", say, "path"):
        planned, path_length, tsp, radius = path_through(space, executed, selection.selected, coarse, config)
    timings["planning"] = sum(timings[k] for k in PLANNING_STAGES)

    return CaseResult(
        executed_views=executed, planned_views=planned,
        coverage=float("nan"), coverage_warm_up=float("nan"), n_views=len(executed) + len(planned), path_length=path_length,
        chamfer_before=alignment.chamfer_before, chamfer_after=alignment.chamfer_after,
        selection=selection, tsp=tsp, timings=timings,
        clouds={"coarse": np.unique(coarse, axis=0), "previous": known.previous,
                "warped": alignment.warped, "inflation": surface.inflated.inflation,
                "planning": surface.inflated.planning},
        obstacle=(centre, radius), warnings=warnings, planning_target=problem.planning_target,
        planning_organs=planning_organ_shares(problem, selection, surface.organs),
    )


def planning_organ_shares(problem, selection, organs) -> dict:
    """Organ -> the share of its predicted planning voxels (coverable by some view) the executed
    and selected views see; empty without organ labels."""
    if organs is None:
        return {}
    matrix = sparse.csr_matrix(problem.visibility)
    views = [*problem.executed, *selection.selected]
    return organ_shares(covered_voxels(matrix, views), oracle_voxels(matrix), organs)


def _registration_warnings(known: Known, alignment, config: PlantConfig) -> list:
    """A registration that ends far from the coarse scan for the plant's size means the two scans
    are hardly two sessions of one plant; said in the scans' own units."""
    size = config.scene.largest_side
    fraction = alignment.chamfer_after / size
    if fraction <= config.registration.warn_chamfer_fraction:
        return []
    # Scan metres, in mm for a plant under a metre (as read with --units mm or auto), else in m
    # (as read with --units m: the user sees the numbers of the files).
    per_scan, unit = 1.0 / known.scan_scale, "m"
    if size * per_scan < 1.0:
        per_scan, unit = 1e3 * per_scan, "mm"
    return [f"registration of {known.names[0]} onto the coarse scan of {known.names[1]} ends at "
            f"{alignment.chamfer_after * per_scan:.3g} {unit} Chamfer ({100 * fraction:.1f} % of the plant's "
            f"{size * per_scan:.3g} {unit}; a matching pair of sessions ends below "
            f"{100 * config.registration.warn_chamfer_fraction:g} %): are these two sessions of the same "
            f"plant? The plan relies on the aligned previous session"]
