"""The planner for a greenhouse row: from what the robot knows to a plan (docs/greenhouse.md).

What it knows (:class:`RowKnown`): the room (its boxes, the passive sweep's 15 views), the
previous session, the coarse reconstruction Q the passive sweep captured with the camera that saw
each point, and the sensor. From that: registration of the previous session onto Q -> voxel
inflation -> PriorTransfer look-at targets and their candidate 6D views (round robin) ->
visibility on the planning surface -> set cover with the passive views as executed -> route
from the end of the sweep. The simulator's ground truth is not here: the simulation
(:mod:`tpvp.simulate.greenhouse`) captures the sweep and executes the plan on it, a real
session (:mod:`tpvp.session.row`) captures them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tpvp.config import RowConfig
from tpvp.errors import PointCloudError
from tpvp.inflation.inflate import inflate_voxels
from tpvp.path.route import ROW_ROUTES
from tpvp.pipeline.result import PlanResult
from tpvp.pipeline.surface import planning_visibility
from tpvp.pipeline.timing import timed
from tpvp.path.tsp import TspConfig
from tpvp.registration.methods import register
from tpvp.setcover.methods import Selection, SelectionProblem, select_views
from tpvp.viewspace.space import ViewSpace
from tpvp.viewspace.lookat import CandidateViews
from tpvp.viewspace.priors import PriorContext, candidate_views

MIN_INSIDE_PLANT_BOX = 0.5  # a row whose points lie mostly outside its room's plant box is in another frame
BOX_TOLERANCE = 0.10  # m: leaves may overhang the plant box a little
PLANNING_STAGES = ("registration", "inflation", "targets", "visibility", "selection", "path")


@dataclass(frozen=True, eq=False)
class RowKnown:
    """What the robot knows of a row before it plans, in the room's (world) frame: the room, the
    previous session (voxel centroids at the ground-truth voxel), the coarse reconstruction Q the
    passive sweep captured and, per point of Q, the position of the first passive view that saw it
    (``passive_cameras``), the sensor; ``timings`` of what came before (the simulation's scene)."""

    room: object  # tpvp.scene.boxes.RoomConfig
    previous: np.ndarray
    coarse: np.ndarray
    passive_cameras: np.ndarray
    sensor: object
    names: tuple = ("previous session", "current session")
    timings: dict = field(default_factory=dict)
    date: str | None = None  # YYYYMMDD of the current session, when known (the authors' look-at files)

    def prior_context(self, voxel: float, transferred: RowTransfer | None = None) -> PriorContext:
        """What the look-at priors know at ``voxel``, after ``transferred`` when given."""
        return PriorContext(self.room, self.coarse, self.passive_cameras, voxel,
                            None if transferred is None else transferred.alignment.warped,
                            None if transferred is None else transferred.inflation.inflation, self.date)


def check_row(points, name: str, room) -> None:
    """Refuse a row that is not where its room expects it (outside the plant box, or in the view box)."""
    inside = room.plant_box.contains(points, tol=BOX_TOLERANCE)
    if inside.mean() < MIN_INSIDE_PLANT_BOX:
        raise PointCloudError(
            f"{name}: only {100 * inside.mean():.1f} % of its points lie in {room.room}'s plant box "
            f"(centre {np.round(room.plant_box.center, 3).tolist()} m): the row is outside its room's boxes "
            f"- is it in the room's frame (metres, aligned to the first capture day)?")
    in_view_box = room.view_box.contains(points).mean()
    if in_view_box > 0.05:
        raise PointCloudError(f"{name}: {100 * in_view_box:.1f} % of its points lie in {room.room}'s view box, "
                              f"where the camera moves: the row is not where its room expects it")


@dataclass(frozen=True, eq=False)
class RowTransfer:
    """The previous session aligned onto the passive reconstruction and inflated."""

    coarse: np.ndarray
    alignment: object  # tpvp.registration.methods.Alignment
    inflation: object  # tpvp.inflation.InflationResult
    timings: dict


def transfer(known: RowKnown, config: RowConfig = RowConfig(), progress=None) -> RowTransfer:
    """Registration of the previous session onto the coarse reconstruction, then voxel inflation
    (region of interest: the cube around the plant box, docs/greenhouse.md#inflation)."""
    say = progress or (lambda stage: None)
    coarse, timings = known.coarse, {}
    with timed(timings, "registration", say, "registration"):
        alignment = register(known.previous, coarse, config.registration, name=known.names[0])
    with timed(timings, "inflation", say, "inflation"):
        box = known.room.plant_box
        inflation = inflate_voxels(alignment.warped, coarse, config.inflation.step, config.inflation.gamma_near,
                                   config.inflation.gamma_far, roi_centre=box.center,
                                   roi_half=1.5 * box.half_extent.max())
    return RowTransfer(coarse, alignment, inflation, timings)


def plan_path(room, positions, config: TspConfig = TspConfig(), with_passive: bool = True, route: str = "band"):
    """The path over the views in ``room`` by ``route`` (:data:`tpvp.path.route.ROW_ROUTES`; bands
    split at the view box's mid height), from where the passive sweep ends when it ran; returns the
    path result and the reported length (sweep included)."""
    split = float(room.view_box.center[2])
    start = np.asarray(room.initial_positions[-1]) if with_passive else None
    result = ROW_ROUTES.get(route)(positions, split, start, config)
    return result, result.length + (room.passive_cost if with_passive else 0.0)


def path_warnings(path, config: TspConfig) -> list[str]:
    """A warning when the band path stopped above its target gap to the lower bound."""
    if path.gap > config.band_gap:
        return [f"band path ends {100 * path.gap:.1f} % above its lower bound (target {100 * config.band_gap:g} %) "
                f"after {config.band_seconds:g} s per band"]
    return []


@dataclass(frozen=True, eq=False)
class PlanningVisibility:
    """What the passive views and the candidates see of the planning surface at one covering voxel.
    Rows: the passive views first (executed), then the candidates in their order."""

    grid: object  # OccupancyGrid of the planning surface at ``resolution``
    view_space: ViewSpace  # the passive views, then the candidates
    matrix: object  # csr (views, planning voxels)
    n_passive: int
    resolution: float

    @property
    def planning_voxels(self) -> int:
        return self.grid.size

    def problem(self, coverage_target: float = 1.0) -> SelectionProblem:
        """The set cover of the planning surface, the passive views counted as executed."""
        return SelectionProblem(self.matrix, tuple(range(self.n_passive)), self.view_space, self.grid.centres,
                                coverage_target)

    def candidate_ids(self, selection: Selection) -> np.ndarray:
        """The selected views as candidate indices (in the selection's order)."""
        return np.asarray(selection.selected, dtype=np.int64) - self.n_passive


def candidate_visibility(room, candidates: CandidateViews, planning_points, resolution: float,
                         sensor) -> PlanningVisibility:
    """:func:`tpvp.pipeline.surface.planning_visibility` of the passive views of ``room``, then the
    candidates."""
    positions = np.concatenate([room.initial_positions, candidates.positions])
    look_ats = np.concatenate([room.initial_look_ats, candidates.look_ats])
    space = ViewSpace(f"{room.room} {candidates.prior} candidates", positions, look_ats,
                      max_range=sensor.max_range, look_at_fixed=False)
    grid, matrix = planning_visibility(planning_points, resolution, positions, look_ats, sensor)
    return PlanningVisibility(grid, space, matrix, len(room.initial_positions), resolution)


@dataclass(frozen=True, eq=False)
class RowCaseResult(PlanResult):
    """A row's plan (:class:`PlanResult`; ``n_views`` and ``path_length`` include the passive sweep)."""

    candidates: CandidateViews
    selected: np.ndarray  # candidate indices in execution order
    path: object  # BandPathResult
    coverage_passive: float
    transfer: RowTransfer
    planning_voxels: int

    @property
    def positions(self) -> np.ndarray:
        return self.candidates.positions[self.selected]

    @property
    def look_ats(self) -> np.ndarray:
        return self.candidates.look_ats[self.selected]

    def summary(self) -> dict:
        alignment = self.transfer.alignment
        return {**self.headline(),
                "passive_views": self.n_views - len(self.selected), "planned_views": len(self.selected),
                "coverage_passive": self.coverage_passive, "planning_voxels": self.planning_voxels,
                "chamfer_before_mm": 1e3 * alignment.chamfer_before, "chamfer_after_mm": 1e3 * alignment.chamfer_after,
                **self.selection_summary(),
                "path_gap": self.path.gap, "path_bound_m": self.path.bound, "warnings": " | ".join(self.warnings),
                **{f"seconds_{k}": v for k, v in self.timings.items()}}


def plan(known: RowKnown, config: RowConfig = RowConfig(), transferred: RowTransfer | None = None,
         progress=None) -> RowCaseResult:
    """Ours on what the robot knows of a row, one block per stage: transfer (unless given), the
    candidates of the configuration's look-at prior (the paper's ``transfer``), their visibility
    on the planning surface, set cover with the passive views as executed, the configuration's
    route (the paper's band path) from the end of the passive sweep. The coverages are NaN:
    the planner has no ground truth (the simulation measures them)."""
    say = progress or (lambda stage: None)
    transferred = transferred or transfer(known, config, progress)
    timings = dict(known.timings) | dict(transferred.timings)
    with timed(timings, "targets", say, "look-at targets"):
        context = known.prior_context(config.inflation.step, transferred)
        candidates = candidate_views(config.candidates, context, config.targets, config.seed)
    with timed(timings, "visibility", say, "visibility"):
        visibility = candidate_visibility(known.room, candidates, transferred.inflation.planning,
                                         config.selection.cover_resolution, config.sensor)
    with timed(timings, "selection", say, "view selection"):
        problem = visibility.problem(config.selection.planning_target(config.view_space))
        selection = select_views(problem, config.selection)
        chosen = visibility.candidate_ids(selection)
    with timed(timings, "path", say, "path"):
        path, length = plan_path(known.room, candidates.positions[chosen], config.path, route=config.route)
        selected = chosen[path.order]
    timings["planning"] = sum(timings[k] for k in PLANNING_STAGES)
    return RowCaseResult(candidates=candidates, selected=selected, path=path, coverage_passive=float("nan"),
                         transfer=transferred, planning_voxels=visibility.planning_voxels,
                         n_views=visibility.n_passive + len(selected), coverage=float("nan"), path_length=length,
                         selection=selection, timings=timings, warnings=path_warnings(path, config.path))


