"""The planner, plants and rows alike: from what the robot knows to a plan.

What it knows (:class:`Known`): the previous session's model, the sensor, and the views executed
before it plans with what they observed (a plant's initial view and warm-up NBVs, held by the NBV
method given to :func:`transfer`; a row's passive sweep, its reconstruction in ``Known.coarse``).
From that, one path for both settings (the configuration's ``stages``):

1. :func:`transfer`: registration of the previous model onto what the executed views saw;
2. :func:`planning_surface`: inflation, the candidate views, the planning grid and what each
   view sees of it (ray casting);
3. :func:`plan`: the view selection (set cover, the executed views fixed), then the route.

What differs between the settings, and why, is one table (:data:`SETTINGS`): how inflation
bounds its growth (a plant: the cube of its predicted size around the planning frame's centre; a
row: the cube around its room's plant box, by voxel morphology), where the candidate views come
from (a plant's view space; a row's look-at prior, after its passive sweep), the route (a plant's
open path around its obstacle sphere after the warm-up; a row's band path from the end of the
sweep), and the registration check (a plant's Chamfer against its size). Every stage's method is
chosen by name in the configuration (:class:`tpvp.config.PlantConfig`,
:class:`tpvp.config.RowConfig`). The simulator's ground truth is not here: the simulation
(:mod:`tpvp.simulate`) executes the views on it, a real session (:mod:`tpvp.session`) captures them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy import sparse

from tpvp.errors import ConfigError
from tpvp.inflation.inflate import inflate, inflate_voxels
from tpvp.inflation.weights import surface_area, surface_classes, surface_weights
from tpvp.path.local import predicted_size
from tpvp.path.route import path_through, row_path, row_path_warnings
from tpvp.pipeline.surface import planning_visibility, with_captures_seen
from tpvp.pipeline.timing import timed
from tpvp.registration.methods import register
from tpvp.scene.frame import scan_points
from tpvp.scene.organs import CODE, organ_shares, voxel_organs
from tpvp.scene.voxels import contains_keys, dilate_keys
from tpvp.setcover.methods import SelectionProblem, select_views
from tpvp.setcover.miss_model import VIEW_SPACES as MISS_VIEW_SPACES, load_miss_model, planning_features
from tpvp.viewspace.priors import PriorContext, candidate_views
from tpvp.viewspace.space import ViewSpace
from tpvp.visibility import covered_voxels, oracle_voxels

#: The planner's stages, timed under these keys; ``timings["planning"]`` is their sum.
PLANNING_STAGES = ("registration", "inflation", "targets", "visibility", "selection", "path")


@dataclass(frozen=True, eq=False)
class Known:
    """What the robot knows before it plans, in the planning frame: the previous session's model
    (``previous``), the sensor and the session names; a plant's candidate views (``view_space``),
    the planning frame itself (``plant_from_scan``: scan metres -> planning frame, scale included),
    the supporting table and the previous model's organ labels; a row's room (its boxes, candidate
    positions and passive sweep), the passive sweep's reconstruction Q (``coarse``) with, per point,
    the first passive view that saw it (``passive_cameras``) and the session's date. ``timings``:
    what came before (the simulation's scene). Nothing of today's plant but what the executed
    views observe."""

    previous: np.ndarray
    sensor: object  # SensorConfig in the planning frame
    names: tuple = ("previous session", "current session")  # as the user named them
    view_space: object = None  # tpvp.viewspace.ViewSpace of a plant (a row's candidates come from its look-at prior)
    plant_from_scan: np.ndarray = field(default_factory=lambda: np.eye(4))
    table_points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    reduction: dict = field(default_factory=dict)
    previous_organs: np.ndarray | None = None  # organ code of each previous point (tpvp.scene.organs), if labelled
    room: object = None  # tpvp.scene.boxes.RoomConfig of a row
    coarse: np.ndarray | None = None  # a row's passive reconstruction (a plant's: its NBV's observations)
    passive_cameras: np.ndarray | None = None
    timings: dict = field(default_factory=dict)
    date: str | None = None  # YYYYMMDD of today's row session, when known (the authors' look-at files)

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

    def prior_context(self, voxel: float, warped=None, inflation=None) -> PriorContext:
        """What a row's look-at priors know at ``voxel``; ``warped`` and ``inflation`` once registered."""
        return PriorContext(self.room, self.coarse, self.passive_cameras, voxel, warped, inflation, self.date)


@dataclass(frozen=True, eq=False)
class Transfer:
    """The executed views (indices of the views the selection fixes), what they observed (the
    coarse reconstruction Q) and the previous session aligned onto it."""

    nbv: object  # a plant's NBV method object, holding the executed views' state (None for a row)
    executed: list
    coarse: np.ndarray  # observed points (a plant's duplicates kept, as the reference feeds registration)
    alignment: object  # tpvp.registration.methods.Alignment
    timings: dict  # registration (s); the simulation adds warm_up
    warnings: list


def transfer(known: Known, config, nbv=None, progress=None) -> Transfer:
    """Registration of the previous session onto what the executed views saw: ``nbv``'s
    observations (a plant's initial view and warm-up NBVs, from the simulator or a session's
    captures) or, without ``nbv``, the passive sweep's reconstruction ``known.coarse``."""
    say = progress or (lambda stage: None)
    if nbv is None:
        coarse, executed = known.coarse, list(range(len(known.room.initial_positions)))
    else:
        coarse, executed = np.concatenate(nbv.observations), list(nbv.executed)
    timings = {}
    with timed(timings, "registration", say, "registration"):
        alignment = register(known.previous, coarse, config.registration, name=known.names[0])
    return Transfer(nbv, executed, coarse, alignment, timings, SETTINGS[config.setting].check(known, alignment, config))


@dataclass(frozen=True, eq=False)
class PlanningSurface:
    """The planning surface of a case and what the views see of it: the inflation's result
    (P~ u Q u I), the views (``view_space``: a plant's candidates; a row's passive views, then its
    candidates, ``candidates``), the planning grid, the (views x planning voxels) visibility, the
    class and the area of each planning voxel (:mod:`tpvp.inflation.weights`), the organ of each
    when the previous model is labelled, and the stage timings."""

    inflated: object  # tpvp.inflation.InflationResult
    view_space: object  # tpvp.viewspace.ViewSpace
    grid: object  # tpvp.scene.grid.OccupancyGrid
    visibility: object
    timings: dict
    candidates: object = None  # a row's tpvp.viewspace.lookat.CandidateViews
    classes: np.ndarray | None = None  # None unless config.surface_weights.enabled
    area: np.ndarray | None = None
    organs: np.ndarray | None = None


def inflated(known: Known, config, transferred: Transfer):
    """The inflation of the aligned previous session against Q (:mod:`tpvp.inflation.inflate`)."""
    return SETTINGS[config.setting].inflate(known, config, transferred.alignment.warped, transferred.coarse)


def planning_surface(known: Known, config, transferred: Transfer, progress=None) -> PlanningSurface:
    """Inflation, the candidate views, the planning grid with its voxel classes, and visibility."""
    say = progress or (lambda stage: None)
    timings = {}
    warped, coarse = transferred.alignment.warped, transferred.coarse
    with timed(timings, "inflation", say, "inflation"):
        inflation = inflated(known, config, transferred)
    setting = SETTINGS[config.setting]
    if setting.candidates is None:
        space, candidates = known.view_space, None
    else:
        with timed(timings, "targets", say, "look-at targets"):
            space, candidates = setting.candidates(known, config, warped, inflation)
    with timed(timings, "visibility", say, "visibility"):
        resolution = config.selection.cover_resolution
        grid, visibility = planning_visibility(inflation.planning, resolution, space.positions, space.look_ats,
                                               known.sensor)
        if config.selection.captures_seen and transferred.nbv is not None:
            visibility = with_captures_seen(visibility, grid, transferred.nbv.executed,
                                            transferred.nbv.observations)
        classes = area = None  # only a weighted coverage target reads them
        weights = _class_weights(config)
        if weights is not None and weights.enabled:
            classes = surface_classes(grid.keys, resolution, warped, coarse, weights.near_voxels * resolution)
            area = surface_area(grid.keys, resolution, inflation.planning) if weights.area else None
        # The previous model's labels follow the registration (a method that warps it point by
        # point); voxels of growth or of today's captures alone hold no labelled point: unknown.
        labelled = known.previous_organs is not None and len(known.previous_organs) == len(warped)
        organs = voxel_organs(grid.keys, resolution, warped, known.previous_organs) if labelled else None
    return PlanningSurface(inflation, space, grid, visibility, timings, candidates, classes, area, organs)


def _class_weights(config):
    """The planning surface's class weights (a plant's; a row's surface has no classes)."""
    return getattr(config, "surface_weights", None)


def case_features(config, transferred: Transfer, surface: PlanningSurface) -> dict | None:
    """What the per-case miss model reads of this plan (:func:`tpvp.setcover.miss_model.planning_features`;
    every plan it predicts, whichever rule sets its planning target), or None where it predicts
    nothing: a coverage target of 1, a re-planned plan, a row, a view space it was not calibrated on."""
    selection = config.selection
    if (selection.coverage_target >= 1.0 or selection.replan_after or config.setting != "plant"
            or config.view_space not in MISS_VIEW_SPACES):
        return None
    return planning_features(config, transferred, surface)


def _per_case(config) -> bool:
    """Whether the per-case model sets the planning target where it applies (else the constant rule)."""
    selection = config.selection
    return selection.miss_model == "per-case" and selection.planning_miss_ratio is None


def selection_problem(known: Known, config, transferred: Transfer, surface: PlanningSurface,
                      features: dict | None = None) -> SelectionProblem:
    """The view selection on ``surface``: the executed views, the planning target of the coverage
    target (per case from ``features``, :func:`case_features`, computed when not given and the
    per-case rule applies) and, below a target of 1, the voxels' class weights
    (``config.surface_weights``)."""
    selection, classes = config.selection, _class_weights(config)
    weights = None
    if selection.coverage_target < 1.0 and classes is not None and classes.enabled:
        weights = surface_weights(surface.classes, classes, surface.area)
    if _per_case(config) and features is None:
        features = case_features(config, transferred, surface)
    target = (load_miss_model().planning_target_for(features, selection.coverage_target)
              if _per_case(config) and features is not None else selection.planning_target(config.view_space))
    targets = selection.organ_target_values()
    groups, shares = (organ_groups(surface.organs, targets, target, known.names[0], surface.grid.keys,
                                   selection.organ_margin_voxels) if targets else (None, None))
    return SelectionProblem(surface.visibility, tuple(transferred.executed), surface.view_space,
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


@dataclass(frozen=True, eq=False, kw_only=True)
class PlanResult:
    """A plan: the views executed before it (``executed_views``) and the planned ones in execution
    order (``planned_views``), both indices of ``view_space``; the path, the view selection, the
    stage times and the warnings in the user's terms. ``n_views`` counts the executed views, as the
    paper does; ``path_length`` is the whole route (a plant's in the planning frame, a row's passive
    sweep included). The planner leaves the coverages NaN: it has no ground truth (the simulation
    measures them, ``coverage_captured`` for the executed views alone). A plant's plan adds its
    obstacle sphere, re-plans and organ shares; a row's its look-at candidates."""

    setting: str  # "plant" or "row"
    n_views: int
    coverage: float
    path_length: float  # m
    selection: object  # tpvp.setcover.methods.Selection
    timings: dict
    warnings: list = field(default_factory=list)
    view_space: object  # tpvp.viewspace.ViewSpace
    executed_views: list
    planned_views: list
    coverage_captured: float
    transfer: Transfer
    path: object  # the route's result (tpvp.path.tsp.PathResult / BandPathResult)
    clouds: dict  # coarse, previous, warped, inflation, planning (for figures and recordings)
    planning_target: float = 1.0  # fraction of the planning surface the selection had to see
    planning_voxels: int = 0
    obstacle: tuple | None = None  # a plant's (centre, radius) of the path's collision sphere
    candidates: object = None  # a row's tpvp.viewspace.lookat.CandidateViews
    replans: tuple = ()  # tpvp.pipeline.replan.Replan rows, in order (selection.replan_after)
    planning_organs: dict = field(default_factory=dict)  # organ -> share of its predicted voxels the plan sees
    organ_coverage: dict = field(default_factory=dict)  # organ -> true coverage (the simulation measures it)
    # the per-case miss model's predicted true coverage and its lower bound (NaN where it does not apply)
    predicted_coverage: float = float("nan")
    predicted_coverage_lower: float = float("nan")

    @property
    def order(self) -> list:
        """Every executed view in execution order: the executed views, then the planned ones."""
        return list(self.executed_views) + list(self.planned_views)

    @property
    def positions(self) -> np.ndarray:
        """The planned views' positions, in execution order."""
        return self.view_space.positions[np.asarray(self.planned_views, dtype=np.int64)]

    @property
    def look_ats(self) -> np.ndarray:
        return self.view_space.look_ats[np.asarray(self.planned_views, dtype=np.int64)]

    @property
    def planned_candidates(self) -> np.ndarray:
        """A row's planned views as indices of its candidates (the passive views come first)."""
        return np.asarray(self.planned_views, dtype=np.int64) - len(self.executed_views)

    @property
    def chamfer_before(self) -> float:
        """Transferred model vs coarse reconstruction before registration (m, planning frame)."""
        return self.transfer.alignment.chamfer_before

    @property
    def chamfer_after(self) -> float:
        return self.transfer.alignment.chamfer_after

    @property
    def set_cover(self):
        """The set-cover solver's own result (bound, gap, dropped voxels), when that method ran."""
        return self.selection.details

    def summary(self) -> dict:
        """One row of results: the same columns for every plan of a setting."""
        return SETTINGS[self.setting].summary(self)

    def seconds(self) -> dict:
        return {f"seconds_{k}": v for k, v in self.timings.items()}

    def headline(self) -> dict:
        """The summary's first columns, the same for every setting."""
        return {"views": self.n_views, "coverage": self.coverage, "path_length_m": self.path_length}

    def selection_summary(self) -> dict:
        return {"selection_optimal": bool(self.selection.optimal), "selection_status": self.selection.status}


def plan(known: Known, config, transferred: Transfer | None = None, progress=None,
         surface: PlanningSurface | None = None) -> PlanResult:
    """The plan after :func:`transfer` (computed when not given; a plant's needs its NBV's
    transfer): the planning surface (``surface`` when already computed: plans that differ only in
    the selection share it), the view selection with the executed views fixed, the route. The
    result's coverages are NaN: the planner has no ground truth (the simulation fills them in)."""
    say = progress or (lambda stage: None)
    transferred = transferred or transfer(known, config, progress=progress)
    timings = dict(known.timings) | dict(transferred.timings)
    surface = surface or planning_surface(known, config, transferred, progress)
    timings.update(surface.timings)
    with timed(timings, "selection", say, "view selection"):
        features = case_features(config, transferred, surface)
        problem = selection_problem(known, config, transferred, surface, features)
        selection = select_views(problem, config.selection)
    predicted = (load_miss_model().predicted_coverage(features, problem.planning_target) if features is not None
                 else (float("nan"), float("nan")))
    with timed(timings, "path", say, "path"):
        route = SETTINGS[config.setting].route(known, config, transferred, surface, selection.selected)
    timings["planning"] = sum(timings[k] for k in PLANNING_STAGES if k in timings)
    executed = transferred.executed
    return PlanResult(
        setting=config.setting, n_views=len(executed) + len(route.planned), coverage=float("nan"),
        path_length=route.length, selection=selection, timings=timings,
        warnings=list(transferred.warnings) + route.warnings, view_space=surface.view_space,
        executed_views=executed, planned_views=route.planned, coverage_captured=float("nan"),
        transfer=transferred, path=route.path,
        clouds={"coarse": np.unique(transferred.coarse, axis=0), "previous": known.previous,
                "warped": transferred.alignment.warped, "inflation": surface.inflated.inflation,
                "planning": surface.inflated.planning},
        planning_target=problem.planning_target, planning_voxels=surface.grid.size, obstacle=route.obstacle,
        candidates=surface.candidates, planning_organs=planning_organ_shares(problem, selection, surface.organs),
        predicted_coverage=predicted[0], predicted_coverage_lower=predicted[1])


def planning_organ_shares(problem, selection, organs) -> dict:
    """Organ -> the share of its predicted planning voxels (coverable by some view) the executed
    and selected views see; empty without organ labels."""
    if organs is None:
        return {}
    matrix = sparse.csr_matrix(problem.visibility)
    views = [*problem.executed, *selection.selected]
    return organ_shares(covered_voxels(matrix, views), oracle_voxels(matrix), organs)


# ---------------------------------------------------------------- what differs between the settings
@dataclass(frozen=True)
class Route:
    """The route's result: the planned views in execution order, the whole length, the path
    solver's result, a plant's obstacle sphere and the route's warnings."""

    planned: list
    length: float
    path: object
    obstacle: tuple | None = None
    warnings: list = field(default_factory=list)


def _plant_inflation(known, config, warped, coarse):
    """Growth is looked for in the cube of the plant's predicted size around the planning frame's centre."""
    centre = np.zeros(3)
    return inflate(warped, coarse, centre, predicted_size(coarse, centre), config.inflation)


def _row_inflation(known, config, warped, coarse):
    """A row spans metres: voxel morphology in the cube around the room's plant box
    (docs/greenhouse.md#inflation)."""
    box, inflation = known.room.plant_box, config.inflation
    return inflate_voxels(warped, coarse, inflation.step, inflation.gamma_near, inflation.gamma_far,
                          roi_centre=box.center, roi_half=1.5 * box.half_extent.max())


def _row_candidates(known, config, warped, inflation):
    """A row's views: the passive sweep's (executed), then the configuration's look-at prior's
    candidates (the paper's ``transfer``: targets on what registration and inflation predict)."""
    context = known.prior_context(config.inflation.step, warped, inflation.inflation)
    candidates = candidate_views(config.candidates, context, config.targets, config.seed)
    return row_view_space(known.room, candidates, known.sensor), candidates


def row_view_space(room, candidates, sensor) -> ViewSpace:
    """A row's views: the passive sweep of ``room``, then ``candidates`` (their look-ats chosen)."""
    return ViewSpace(f"{room.room} {candidates.prior} candidates",
                     np.concatenate([room.initial_positions, candidates.positions]),
                     np.concatenate([room.initial_look_ats, candidates.look_ats]),
                     max_range=sensor.max_range, look_at_fixed=False)


def _plant_route(known, config, transferred, surface, selected) -> Route:
    """The warm-up's path, then the shortest open path from its last view around the obstacle sphere."""
    planned, length, tsp, radius = path_through(surface.view_space, transferred.executed, selected,
                                                transferred.coarse, config)
    return Route(planned, length, tsp, (np.zeros(3), radius))


def _row_route(known, config, transferred, surface, selected) -> Route:
    """The configuration's route over the room (the paper's band path) from the end of the sweep."""
    passive = len(transferred.executed)
    chosen = np.asarray(selected, dtype=np.int64) - passive
    path, length = row_path(known.room, surface.candidates.positions[chosen], config.path, route=config.route)
    return Route((chosen[path.order] + passive).tolist(), length, path, None, row_path_warnings(path, config.path))


def _plant_summary(result: PlanResult) -> dict:
    details = result.selection.details
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
    replans = result.replans
    return {
        **result.headline(),
        "warm_up_views": len(result.executed_views), "planned_views": len(result.planned_views),
        "planning_target": result.planning_target, "coverage_after_warm_up": result.coverage_captured,
        "chamfer_before_mm": 1e3 * result.chamfer_before, "chamfer_after_mm": 1e3 * result.chamfer_after,
        **result.selection_summary(), **solver, "tsp_optimal": result.path.optimal, "tsp_method": result.path.method,
        "warnings": " | ".join(result.warnings),
        **{f"coverage_{organ}": value for organ, value in result.organ_coverage.items()},
        **{f"planning_coverage_{organ}": value for organ, value in result.planning_organs.items()},
        **({"predicted_coverage": result.predicted_coverage, "predicted_coverage_lower": result.predicted_coverage_lower}
           if np.isfinite(result.predicted_coverage) else {}),
        **({"replans": len(replans), "views_added_by_replanning": sum(r.views_added for r in replans),
            "views_dropped_by_replanning": sum(r.views_dropped for r in replans)} if replans else {}),
        **result.seconds(),
    }


def _row_summary(result: PlanResult) -> dict:
    return {**result.headline(),
            "passive_views": len(result.executed_views), "planned_views": len(result.planned_views),
            "coverage_passive": result.coverage_captured, "planning_voxels": result.planning_voxels,
            "chamfer_before_mm": 1e3 * result.chamfer_before, "chamfer_after_mm": 1e3 * result.chamfer_after,
            **result.selection_summary(),
            "path_gap": result.path.gap, "path_bound_m": result.path.bound, "warnings": " | ".join(result.warnings),
            **result.seconds()}


def _registration_warnings(known: Known, alignment, config) -> list:
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


@dataclass(frozen=True)
class Setting:
    """What a setting does its own way in the one planner (each function's doc says why)."""

    inflate: Callable  # (known, config, warped, coarse) -> InflationResult
    candidates: Callable | None  # (known, config, warped, inflation) -> (ViewSpace, CandidateViews); None: known.view_space
    route: Callable  # (known, config, transferred, surface, selected) -> Route
    check: Callable  # (known, alignment, config) -> registration warnings
    summary: Callable  # PlanResult -> its results row (the shipped tables' columns)


#: ``config.setting`` -> :class:`Setting`.
SETTINGS = {
    "plant": Setting(_plant_inflation, None, _plant_route, _registration_warnings, _plant_summary),
    "row": Setting(_row_inflation, _row_candidates, _row_route, lambda known, alignment, config: [], _row_summary),
}
