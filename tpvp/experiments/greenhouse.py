"""One greenhouse-row case of the paper, end to end in the simulator (docs/greenhouse.md).

passive sweep (15 fixed views) -> coarse reconstruction Q -> registration of the previous session
onto Q -> voxel inflation -> PriorTransfer look-at targets -> 800 candidate 6D views (round robin)
-> visibility on the planning surface -> set cover -> band path -> execution on the current
session's ground truth, coverage normalised by the FOV-free oracle (cached on disk). The baselines
of Tables V-VI (the prior ladder with random selection, each prior's upper limit) reuse the same
scene and candidates. The stages live in their packages (the oracle and its cache in
:mod:`tpvp.visibility`, the look-at priors in :mod:`tpvp.viewspace.priors`); this module calls them
in order, with the room and every setting taken from the one :class:`tpvp.config.RowConfig`.
"""

from __future__ import annotations

import time
from contextlib import contextmanager
from dataclasses import dataclass, field, replace

import numpy as np

from tpvp.config import RowConfig
from tpvp.errors import PointCloudError, checked_cloud
from tpvp.inflation import inflate_voxels
from tpvp.path.tsp import TspConfig, band_path
from tpvp.registration.methods import register
from tpvp.scene import voxels
from tpvp.scene.boxes import room_config
from tpvp.scene.grid import build_grid
from tpvp.setcover.methods import Selection, SelectionProblem, select_views
from tpvp.viewspace import ViewSpace
from tpvp.viewspace.lookat import CandidateViews
from tpvp.viewspace.priors import PriorContext, candidate_views
from tpvp.visibility import coverage_ratio, covered_voxels, safe_visibility
from tpvp.visibility.oracle_cache import cached_oracle

MIN_INSIDE_PLANT_BOX = 0.5  # a row whose points lie mostly outside its room's plant box is in another frame
BOX_TOLERANCE = 0.10  # m: leaves may overhang the plant box a little
PLANNING_STAGES = ("registration", "inflation", "targets", "visibility", "selection", "path")


@dataclass(frozen=True, eq=False)
class RowScene:
    """A pair of sessions of one row in the room's (world) frame, the current ground truth, its
    oracle and what the passive sweep saw of it: the voxel ids ``passive_seen``, the centroids of
    the ground truth's points in them (the coarse reconstruction Q, ``coarse``) and, per point of Q, the position of the first passive
    view that saw it (``passive_cameras``)."""

    room: object  # tpvp.scene.boxes.RoomConfig
    previous: np.ndarray  # previous session, voxel centroids at the ground-truth voxel
    current: np.ndarray
    grid: object  # OccupancyGrid of the current ground truth
    oracle: np.ndarray
    passive_visibility: object  # csr (15, voxels)
    passive_seen: np.ndarray
    coarse: np.ndarray
    passive_cameras: np.ndarray
    sensor: object
    names: tuple = ("previous session", "current session")
    timings: dict = field(default_factory=dict)
    oracle_cached: bool = False
    date: str | None = None  # YYYYMMDD of the current session, when known

    def prior_context(self, voxel: float, transferred: RowTransfer | None = None) -> PriorContext:
        """What the look-at priors know of this scene at ``voxel``, after ``transferred`` when given."""
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


def build_row_scene(previous_points, current_points, config: RowConfig = RowConfig(),
                    names=("previous session", "current session"), cache_dir=None, progress=None,
                    date: str | None = None) -> RowScene:
    """Both sessions in the room ``config.view_space``, the current ground truth at
    ``config.gt_resolution``, its oracle (cached on disk, see
    :func:`tpvp.visibility.oracle_cache.cached_oracle`) and the passive sweep's observation.
    ``date`` (YYYYMMDD of the current session) lets the authors' look-at files of that day be used
    as candidates."""
    room_cfg = room_config(config.view_space)
    timings = {}
    t = time.perf_counter()
    previous = checked_cloud(previous_points, names[0])
    current = checked_cloud(current_points, names[1])
    for points, name in ((previous, names[0]), (current, names[1])):
        check_row(points, name, room_cfg)
    resolution = config.gt_resolution
    grid = build_grid(voxels.voxelise(current, resolution), resolution)
    # The previous session feeds registration only: its voxel centroids keep its voxel set.
    previous = voxels.voxel_centroids(previous, resolution)
    timings["scene"] = time.perf_counter() - t

    t = time.perf_counter()
    oracle, from_cache = cached_oracle(grid, room_cfg.view_box.grid(config.oracle_grid), config.sensor.max_range,
                                       cache_dir, progress)
    timings["oracle"] = time.perf_counter() - t
    t = time.perf_counter()
    passive = safe_visibility(grid, room_cfg.initial_positions, room_cfg.initial_look_ats, config.sensor)
    seen = covered_voxels(passive, np.arange(passive.shape[0]))
    first_view = np.asarray(passive.tocsc().argmax(axis=0)).ravel()
    timings["passive"] = time.perf_counter() - t
    if passive.nnz == 0:
        raise PointCloudError(f"{names[1]}: the 15 passive views of {room_cfg.room} observe nothing of it "
                              f"(empty passive scan): is the row in {room_cfg.room}'s frame?")
    if len(oracle) == 0:
        raise PointCloudError(f"{names[1]}: no voxel of the row is visible from {room_cfg.room}'s view box")
    current = voxels.voxel_centroids(current, resolution)
    observed = observed_points(grid, current) if config.coarse == "centroids" else grid.centres
    return RowScene(room_cfg, previous, current, grid, oracle, passive, seen, observed[seen],
                    room_cfg.initial_positions[first_view[seen]], config.sensor, tuple(names), timings, from_cache,
                    date)


def observed_points(grid, centroids) -> np.ndarray:
    """Per voxel of ``grid`` the centroid of the ground-truth points in it (``centroids``: the
    ground truth's :func:`tpvp.scene.voxels.voxel_centroids` at the grid's resolution, the grid's
    key order), the voxel centre where rounding puts a centroid in another voxel. What a view sees
    of a voxel is its points: the reference's coarse cloud is the observed points reduced to 1 cm
    voxel centroids, as the previous session is, so an unchanged row gives Q inside P
    (docs/greenhouse.md#registration); voxel centres would sit up to half a voxel diagonal off P."""
    centres = grid.centres
    if len(centroids) != len(centres):
        return centres
    same = np.all(voxels.voxel_keys(centroids, grid.resolution) == grid.keys, axis=1)
    return np.where(same[:, None], centroids, centres)


@dataclass(frozen=True, eq=False)
class RowTransfer:
    """The previous session aligned onto the passive reconstruction and inflated."""

    coarse: np.ndarray
    alignment: object  # tpvp.registration.methods.Alignment
    inflation: object  # tpvp.inflation.InflationResult
    timings: dict


def row_transfer(scene: RowScene, config: RowConfig = RowConfig(), progress=None) -> RowTransfer:
    """Registration of the previous session onto the coarse reconstruction, then voxel inflation
    (region of interest: the cube around the plant box, docs/greenhouse.md#inflation)."""
    say = progress or (lambda stage: None)
    coarse = scene.coarse
    t = time.perf_counter()
    say("registration")
    alignment = register(scene.previous, coarse, config.registration, name=scene.names[0])
    registration = time.perf_counter() - t
    t = time.perf_counter()
    say("inflation")
    box = scene.room.plant_box
    inflation = inflate_voxels(alignment.warped, coarse, config.inflation.step, config.inflation.gamma_near,
                               config.inflation.gamma_far, roi_centre=box.center, roi_half=1.5 * box.half_extent.max())
    return RowTransfer(coarse, alignment, inflation, {"registration": registration,
                                                       "inflation": time.perf_counter() - t})


def row_candidates(scene: RowScene, prior: str, config: RowConfig = RowConfig(),
                   transferred: RowTransfer | None = None) -> CandidateViews:
    """The candidate views of the look-at prior ``prior`` (a name of
    :data:`tpvp.viewspace.priors.LOOK_AT_PRIORS`: ``obb``, ``passive``, ``transfer``, which needs
    ``transferred``, or ``authors-<prior>``, which needs the scene's date), ``config.targets`` of
    them, surface voxel ``config.inflation.step`` (docs/greenhouse.md#look-at-candidates)."""
    context = scene.prior_context(config.inflation.step, transferred)
    return candidate_views(prior, context, config.targets, config.seed)


def execute(scene: RowScene, positions, look_ats) -> np.ndarray:
    """Ground-truth voxel ids the views observe (the simulator's execution)."""
    return covered_voxels(safe_visibility(scene.grid, positions, look_ats, scene.sensor), np.arange(len(positions)))


def row_coverage(scene: RowScene, seen_ids, with_passive: bool = True) -> float:
    """Oracle-normalised coverage of what the views saw, the passive sweep's voxels added."""
    seen = np.union1d(seen_ids, scene.passive_seen) if with_passive else np.asarray(seen_ids)
    return coverage_ratio(seen, scene.oracle)


def plan_path(scene: RowScene, positions, config: TspConfig = TspConfig(), with_passive: bool = True):
    """Band path over the views (split at the view box's mid height), from where the passive sweep
    ends when it ran; returns the band path result and the reported length (sweep included)."""
    split = float(scene.room.view_box.center[2])
    start = np.asarray(scene.room.initial_positions[-1]) if with_passive else None
    result = band_path(positions, split_height=split, start_position=start, config=config)
    return result, result.length + (scene.room.passive_cost if with_passive else 0.0)


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


def planning_visibility(scene: RowScene, candidates: CandidateViews, planning_points, resolution: float,
                        sensor) -> PlanningVisibility:
    """The planning surface (``planning_points``: the transferred, inflated previous session)
    voxelised at ``resolution`` (the covering voxel), and what each passive view and each candidate
    sees of it through ``sensor`` (ray casting; the dominant cost of planning)."""
    planning_grid = build_grid(voxels.voxelise(planning_points, resolution), resolution)
    room = scene.room
    positions = np.concatenate([room.initial_positions, candidates.positions])
    look_ats = np.concatenate([room.initial_look_ats, candidates.look_ats])
    space = ViewSpace(f"{room.room} transfer candidates", positions, look_ats, max_range=sensor.max_range,
                      look_at_fixed=False)
    matrix = safe_visibility(planning_grid, positions, look_ats, sensor)
    return PlanningVisibility(planning_grid, space, matrix, len(room.initial_positions), resolution)


@contextmanager
def timed(timings: dict, key: str, say, stage: str):
    """Reports ``stage`` to ``say`` (a progress callback) and times the block into ``timings[key]``."""
    say(stage)
    t = time.perf_counter()
    yield
    timings[key] = time.perf_counter() - t


@dataclass(frozen=True, eq=False)
class RowCaseResult:
    candidates: CandidateViews
    selected: np.ndarray  # candidate indices in execution order
    path: object  # BandPathResult
    coverage: float
    coverage_passive: float
    n_views: int  # passive views included
    path_length: float  # passive sweep included (m)
    selection: object
    transfer: RowTransfer
    planning_voxels: int
    timings: dict
    warnings: list = field(default_factory=list)

    @property
    def positions(self) -> np.ndarray:
        return self.candidates.positions[self.selected]

    @property
    def look_ats(self) -> np.ndarray:
        return self.candidates.look_ats[self.selected]

    def summary(self) -> dict:
        alignment = self.transfer.alignment
        return {"views": self.n_views, "coverage": self.coverage, "path_length_m": self.path_length,
                "passive_views": self.n_views - len(self.selected), "planned_views": len(self.selected),
                "coverage_passive": self.coverage_passive, "planning_voxels": self.planning_voxels,
                "chamfer_before_mm": 1e3 * alignment.chamfer_before, "chamfer_after_mm": 1e3 * alignment.chamfer_after,
                "selection_optimal": bool(self.selection.optimal), "selection_status": self.selection.status,
                "path_gap": self.path.gap, "path_bound_m": self.path.bound, "warnings": " | ".join(self.warnings),
                **{f"seconds_{k}": v for k, v in self.timings.items()}}


def run_row_case(scene: RowScene, config: RowConfig = RowConfig(), progress=None,
                 transferred: RowTransfer | None = None) -> RowCaseResult:
    """Ours on one row pair, one block per stage: transfer, the transfer prior's candidates, their
    visibility on the planning surface, set cover with the passive views as executed, band path from
    the end of the passive sweep, execution. ``transferred``: :func:`row_transfer` of this scene."""
    result = plan_row_case(scene, config, progress, transferred)
    timings = dict(result.timings)
    with timed(timings, "execution", progress or (lambda stage: None), "execution"):
        coverage = row_coverage(scene, execute(scene, result.positions, result.look_ats))
    return replace(result, coverage=coverage, coverage_passive=row_coverage(scene, []), timings=timings)


def plan_row_case(scene, config: RowConfig = RowConfig(), progress=None,
                  transferred: RowTransfer | None = None) -> RowCaseResult:
    """:func:`run_row_case` without the execution: the coverages are NaN (a real session has no
    ground truth). ``scene`` needs the room, the previous session, the coarse reconstruction and
    its passive cameras, the sensor, names and timings."""
    say = progress or (lambda stage: None)
    transferred = transferred or row_transfer(scene, config, progress)
    timings = dict(scene.timings) | dict(transferred.timings)
    with timed(timings, "targets", say, "look-at targets"):
        context = scene.prior_context(config.inflation.step, transferred)
        candidates = candidate_views("transfer", context, config.targets, config.seed)
    with timed(timings, "visibility", say, "visibility"):
        visibility = planning_visibility(scene, candidates, transferred.inflation.planning,
                                         config.selection.cover_resolution, config.sensor)
    with timed(timings, "selection", say, "view selection"):
        problem = visibility.problem(config.selection.planning_target(config.view_space))
        selection = select_views(problem, config.selection)
        chosen = visibility.candidate_ids(selection)
    with timed(timings, "path", say, "path"):
        path, length = plan_path(scene, candidates.positions[chosen], config.path)
        selected = chosen[path.order]
    timings["planning"] = sum(timings[k] for k in PLANNING_STAGES)
    return RowCaseResult(candidates, selected, path, float("nan"), float("nan"),
                         visibility.n_passive + len(selected), length, selection, transferred,
                         visibility.planning_voxels, timings, path_warnings(path, config.path))


def candidate_truth(scene: RowScene, candidates: CandidateViews):
    """What each candidate view observes of the ground truth (csr, candidates x voxels)."""
    return safe_visibility(scene.grid, candidates.positions, candidates.look_ats, scene.sensor)


def upper_limit(scene: RowScene, truth) -> float:
    """Table V: the largest fraction of the oracle any subset of the candidates reaches (all of
    them together; the passive views not added)."""
    return row_coverage(scene, covered_voxels(truth, np.arange(truth.shape[0])), with_passive=False)


def random_selection(scene: RowScene, candidates: CandidateViews, truth, budget: int, repetition: int,
                     config: RowConfig = RowConfig(), with_passive: bool = True) -> dict:
    """A random one-shot baseline: ``budget`` of the candidates drawn uniformly (seeded by the
    configuration's seed and ``repetition``), the same band path, executed. Views and path include
    the passive sweep when ``with_passive`` (PriorPassive/PriorTransfer use it; PriorOBB does not)."""
    rng = np.random.default_rng([config.seed, int(repetition), int(budget)])
    chosen = rng.choice(len(candidates), size=min(int(budget), len(candidates)), replace=False)
    t = time.perf_counter()
    path, length = plan_path(scene, candidates.positions[chosen], config.path, with_passive)
    seconds = time.perf_counter() - t
    coverage = row_coverage(scene, covered_voxels(truth, chosen), with_passive)
    n_passive = len(scene.room.initial_positions) if with_passive else 0
    return {"budget": int(budget), "repetition": int(repetition), "views": n_passive + len(chosen),
            "coverage": coverage, "path_length_m": length, "path_gap": path.gap, "seconds_path": seconds}
