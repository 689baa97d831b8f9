"""One greenhouse-row case of the paper, end to end in the simulator (docs/greenhouse.md).

passive sweep (15 fixed views) -> coarse reconstruction Q -> registration of the previous session
onto Q -> voxel inflation -> PriorTransfer look-at targets -> 800 candidate 6D views (round robin)
-> visibility on the planning surface -> set cover -> band path -> execution on the current
session's ground truth, coverage normalised by the FOV-free oracle (cached on disk). The baselines
of Tables V-VI (the prior ladder with random selection, each prior's upper limit) reuse the same
scene and candidates.
"""

from __future__ import annotations

import hashlib
import io
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tpvp.config import RowConfig
from tpvp.errors import ConfigError, PointCloudError, checked_cloud
from tpvp.inflation import inflate_voxels
from tpvp.path.tsp import band_path
from tpvp.registration.methods import register
from tpvp.scene import voxels
from tpvp.scene.boxes import room_config
from tpvp.scene.grid import build_grid
from tpvp.setcover.methods import SelectionProblem, select_views
from tpvp.viewspace import ViewSpace
from tpvp.viewspace.lookat import (CandidateViews, assigned_views, box_targets, passive_targets,
                                   round_robin_views, transfer_targets)
from tpvp.visibility import coverage_ratio, covered_voxels, visibility_matrix
from tpvp.visibility.oracle import greenhouse_oracle

AUTHORS_PRIORS = {"obb": "PriorBBX", "passive": "PriorPassive", "transfer": "PriorTemporal"}
MIN_INSIDE_PLANT_BOX = 0.5  # a row whose points lie mostly outside its room's plant box is in another frame
BOX_TOLERANCE = 0.10  # m: leaves may overhang the plant box a little


def default_cache_dir() -> Path:
    """``$TPVP_CACHE_DIR`` or ``~/.cache/tpvp``: where slow, reusable results (oracles) are kept."""
    return Path(os.environ.get("TPVP_CACHE_DIR") or Path.home() / ".cache" / "tpvp")


def _oracle_key(grid, viewpoints, max_range: float) -> str:
    from tpvp.visibility import oracle as oracle_module

    digest = hashlib.sha256()
    for part in (np.ascontiguousarray(grid.keys, dtype=np.int64).tobytes(),
                 np.ascontiguousarray(grid.countable).tobytes(),
                 np.ascontiguousarray(viewpoints, dtype=np.float64).tobytes(),
                 repr((float(grid.resolution), float(max_range))).encode(),
                 Path(oracle_module.__file__).read_bytes()):  # a changed oracle never reuses old sets
        digest.update(hashlib.sha256(part).digest())
    return digest.hexdigest()[:24]


def cached_oracle(grid, viewpoints, max_range: float, cache_dir=None, progress=None) -> tuple[np.ndarray, bool]:
    """The greenhouse oracle of ``grid`` from ``viewpoints``, read from ``cache_dir/oracle/`` when
    this scene and configuration were computed before (keyed by the voxels, viewpoints, range and
    the oracle's code), computed and stored atomically otherwise. ``cache_dir=False`` disables
    the cache. Returns ``(voxel ids, whether it came from the cache)``."""
    from tpvp.io import atomic_write_bytes

    path = None
    if cache_dir is not False:
        folder = Path(cache_dir) if cache_dir is not None else default_cache_dir()
        path = folder / "oracle" / f"{_oracle_key(grid, viewpoints, max_range)}.npy"
        if path.is_file():
            try:
                return np.load(path, allow_pickle=False), True
            except (OSError, ValueError):
                pass  # a damaged entry is recomputed and replaced
    ids = greenhouse_oracle(grid, viewpoints, max_range, progress=progress)
    if path is not None:
        buffer = io.BytesIO()
        np.save(buffer, ids)
        atomic_write_bytes(path, buffer.getvalue())
    return ids, False


def safe_visibility(grid, positions, look_ats, sensor) -> object:
    """:func:`visibility_matrix`, with an empty row for each view whose camera lies inside an
    occupied voxel (at a coarse covering voxel a position near a leaf can)."""
    from scipy import sparse

    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    look_ats = np.broadcast_to(np.asarray(look_ats, dtype=np.float64).reshape(-1, 3), positions.shape)
    free = np.flatnonzero(~grid.is_occupied(positions))
    seen = visibility_matrix(grid, positions[free], look_ats[free], sensor, progress=False)
    rows = sparse.csr_matrix((np.ones(seen.nnz, bool), seen.indices, seen.indptr), shape=seen.shape).tocoo()
    return sparse.csr_matrix((rows.data, (free[rows.row], rows.col)), shape=(len(positions), grid.size), dtype=bool)


@dataclass(frozen=True, eq=False)
class RowScene:
    """A pair of sessions of one row in the room's (world) frame, the current ground truth, its
    oracle and what the passive sweep saw of it."""

    room: object  # tpvp.scene.boxes.RoomConfig
    previous: np.ndarray  # previous session, voxel centroids at the ground-truth voxel
    current: np.ndarray
    grid: object  # OccupancyGrid of the current ground truth
    oracle: np.ndarray
    passive_visibility: object  # csr (15, voxels)
    sensor: object
    names: tuple = ("previous session", "current session")
    timings: dict = field(default_factory=dict)
    oracle_cached: bool = False
    date: str | None = None  # YYYYMMDD of the current session, when known

    @property
    def passive_seen(self) -> np.ndarray:
        return covered_voxels(self.passive_visibility, np.arange(self.passive_visibility.shape[0]))

    @property
    def coarse(self) -> np.ndarray:
        """The coarse reconstruction Q: centres of the voxels the passive views observed."""
        return self.grid.centres[self.passive_seen]

    def passive_cameras(self) -> np.ndarray:
        """For each point of :attr:`coarse`, the position of the first passive view that saw it."""
        first = np.asarray(self.passive_visibility.tocsc().argmax(axis=0)).ravel()
        return self.room.initial_positions[first[self.passive_seen]]


def _check_row(points, name: str, room) -> None:
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


def build_row_scene(previous_points, current_points, config: RowConfig = RowConfig(), room: str | None = None,
                    names=("previous session", "current session"), cache_dir=None, progress=None,
                    date: str | None = None) -> RowScene:
    """Both sessions, the current ground truth at ``config.gt_resolution``, its oracle (cached on
    disk, see :func:`cached_oracle`) and the passive sweep's observation. ``date`` (YYYYMMDD of the
    current session) lets the authors' look-at files of that day be used as candidates."""
    room_cfg = room_config(room or config.view_space)
    timings = {}
    t = time.perf_counter()
    previous = checked_cloud(previous_points, names[0])
    current = checked_cloud(current_points, names[1])
    for points, name in ((previous, names[0]), (current, names[1])):
        _check_row(points, name, room_cfg)
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
    timings["passive"] = time.perf_counter() - t
    if passive.nnz == 0:
        raise PointCloudError(f"{names[1]}: the 15 passive views of {room_cfg.room} observe nothing of it "
                              f"(empty passive scan): is the row in {room_cfg.room}'s frame?")
    if len(oracle) == 0:
        raise PointCloudError(f"{names[1]}: no voxel of the row is visible from {room_cfg.room}'s view box")
    return RowScene(room_cfg, previous, voxels.voxel_centroids(current, resolution), grid, oracle, passive,
                    config.sensor, tuple(names), timings, from_cache, date)


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
    alignment = register(scene.previous, coarse, config.registration)
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
    """The prior's 100 look-at targets and their 800 candidate views (docs/greenhouse.md#look-at-candidates).

    ``obb`` uses the room's own targets (the authors' Poisson-disk sample) when it has 100 of
    them, ``passive`` the surface frontiers of the passive reconstruction, ``transfer`` the
    transferred surface the passive sweep missed (needs ``transferred``); ``authors-<prior>`` reads
    the authors' own assignment of that prior for the scene's date (bundled ``gap_1`` files, made
    on the real rows)."""
    room, targets_config, seed = scene.room, config.targets, config.seed
    voxel = config.inflation.step
    if prior.startswith("authors-") and prior[len("authors-"):] in AUTHORS_PRIORS:
        from tpvp.scene.boxes import candidate_look_ats

        if scene.date is None:
            raise ConfigError(f"the {prior} candidates need the session's date (build_row_scene(..., date=))")
        table = candidate_look_ats(room.room, scene.date, AUTHORS_PRIORS[prior[len("authors-"):]], room.folder)
        return assigned_views(room.candidate_positions, table, prior)
    if prior == "obb":
        targets = (np.asarray(room.rand_look_at_points) if len(room.rand_look_at_points) == targets_config.count
                   else box_targets(room.plant_box, targets_config.count, seed))
    elif prior == "passive":
        targets = passive_targets(scene.passive_cameras(), scene.coarse, voxel, targets_config.count, seed,
                                  box=room.plant_box)
    elif prior == "transfer":
        if transferred is None:
            raise ConfigError("the transfer prior needs the registered previous session (row_transfer)")
        targets = transfer_targets(transferred.alignment.warped, transferred.coarse,
                                   transferred.inflation.inflation, voxel, targets_config.count, seed)
    else:
        raise ConfigError(f"unknown look-at prior {prior!r}; choose one of obb, passive, transfer, "
                          f"authors-obb, authors-passive, authors-transfer")
    return round_robin_views(targets, room.candidate_positions, targets_config.rounds, seed, prior)


def execute(scene: RowScene, positions, look_ats) -> np.ndarray:
    """Ground-truth voxel ids the views observe (the simulator's execution)."""
    return covered_voxels(safe_visibility(scene.grid, positions, look_ats, scene.sensor), np.arange(len(positions)))


def row_coverage(scene: RowScene, seen_ids, with_passive: bool = True) -> float:
    """Oracle-normalised coverage of what the views saw, the passive sweep's voxels added."""
    seen = np.union1d(seen_ids, scene.passive_seen) if with_passive else np.asarray(seen_ids)
    return coverage_ratio(seen, scene.oracle)


def passive_end(scene: RowScene) -> np.ndarray:
    """Where the passive sweep ends: the planned path starts there."""
    return np.asarray(scene.room.initial_positions[-1])


def plan_path(scene: RowScene, positions, config: RowConfig, with_passive: bool = True):
    """Band path over the views (split at the view box's mid height), from the end of the passive
    sweep when it ran; returns the band path result and the reported length (sweep included)."""
    split = float(scene.room.view_box.center[2])
    start = passive_end(scene) if with_passive else None
    result = band_path(positions, split_height=split, start_position=start, config=config.path)
    return result, result.length + (scene.room.passive_cost if with_passive else 0.0)


@dataclass(frozen=True, eq=False)
class PlanningVisibility:
    """What the passive views and the candidates see of the planning surface at one covering voxel.
    Rows: the passive views first (executed), then the candidates in their order."""

    grid: object  # OccupancyGrid of the planning surface at ``resolution``
    positions: np.ndarray  # (passive + candidates, 3)
    look_ats: np.ndarray
    matrix: object  # csr (views, planning voxels)
    n_passive: int
    resolution: float

    @property
    def planning_voxels(self) -> int:
        return self.grid.size


def planning_visibility(scene: RowScene, candidates: CandidateViews, transferred: RowTransfer,
                        config: RowConfig = RowConfig()) -> PlanningVisibility:
    """Stage "visibility" of :func:`run_row_case`: the planning surface (the transferred, inflated
    previous session) voxelised at ``config.selection.cover_resolution``, and what each passive
    view and each candidate sees of it (ray casting; the dominant cost of planning)."""
    resolution = config.selection.cover_resolution
    planning_grid = build_grid(voxels.voxelise(transferred.inflation.planning, resolution), resolution)
    room = scene.room
    positions = np.concatenate([room.initial_positions, candidates.positions])
    look_ats = np.concatenate([room.initial_look_ats, candidates.look_ats])
    matrix = safe_visibility(planning_grid, positions, look_ats, config.sensor)
    return PlanningVisibility(planning_grid, positions, look_ats, matrix, len(room.initial_positions), resolution)


def select_row_views(scene: RowScene, visibility: PlanningVisibility, config: RowConfig = RowConfig()):
    """Stage "selection" of :func:`run_row_case`: the set cover over the planning surface with the
    passive views counted as executed. Returns ``(selection result, chosen candidate indices)``
    (indices into the candidates, in the solver's order)."""
    space = ViewSpace(f"{scene.room.room} transfer candidates", visibility.positions, visibility.look_ats,
                      max_range=config.sensor.max_range, look_at_fixed=False)
    problem = SelectionProblem(visibility.matrix, tuple(range(visibility.n_passive)), space, visibility.grid.centres,
                               config.selection.planning_target(config.view_space))
    selection = select_views(problem, config.selection)
    return selection, np.asarray(selection.selected, dtype=np.int64) - visibility.n_passive


def order_row_views(scene: RowScene, candidates: CandidateViews, chosen, config: RowConfig = RowConfig()):
    """Stage "path" of :func:`run_row_case`: the band path over the chosen candidates from the end
    of the passive sweep. Returns ``(band path result, reported length (m, sweep included),
    candidate indices in execution order)``."""
    chosen = np.asarray(chosen, dtype=np.int64)
    path, length = plan_path(scene, candidates.positions[chosen], config)
    return path, length, chosen[path.order]


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
    """Ours on one row pair: transfer (:func:`row_transfer`), candidates (:func:`row_candidates`),
    visibility on the planning surface at ``config.selection.cover_resolution``
    (:func:`planning_visibility`), set cover with the passive views as executed
    (:func:`select_row_views`), band path (:func:`order_row_views`), execution. ``transferred``:
    :func:`row_transfer` of this scene when already computed."""
    say = progress or (lambda stage: None)
    transferred = transferred or row_transfer(scene, config, progress)
    timings = dict(scene.timings) | dict(transferred.timings)

    t = time.perf_counter()
    say("look-at targets")
    candidates = row_candidates(scene, "transfer", config, transferred)
    timings["targets"] = time.perf_counter() - t

    t = time.perf_counter()
    say("visibility")
    visibility = planning_visibility(scene, candidates, transferred, config)
    timings["visibility"] = time.perf_counter() - t

    t = time.perf_counter()
    say("view selection")
    selection, chosen = select_row_views(scene, visibility, config)
    timings["selection"] = time.perf_counter() - t

    t = time.perf_counter()
    say("path")
    path, length, selected = order_row_views(scene, candidates, chosen, config)
    timings["path"] = time.perf_counter() - t
    timings["planning"] = sum(timings[k] for k in ("registration", "inflation", "targets", "visibility",
                                                   "selection", "path"))

    t = time.perf_counter()
    say("execution")
    coverage = row_coverage(scene, execute(scene, candidates.positions[selected], candidates.look_ats[selected]))
    timings["execution"] = time.perf_counter() - t
    warnings = []
    if path.gap > config.path.band_gap:
        warnings.append(f"band path ends {100 * path.gap:.1f} % above its lower bound (target "
                        f"{100 * config.path.band_gap:g} %) after {config.path.band_seconds:g} s per band")
    n_passive = visibility.n_passive
    return RowCaseResult(candidates, selected, path, coverage, row_coverage(scene, []), n_passive + len(selected),
                         length, selection, transferred, visibility.planning_voxels, timings, warnings)


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
    path, length = plan_path(scene, candidates.positions[chosen], config, with_passive)
    seconds = time.perf_counter() - t
    coverage = row_coverage(scene, covered_voxels(truth, chosen), with_passive)
    n_passive = len(scene.room.initial_positions) if with_passive else 0
    return {"budget": int(budget), "repetition": int(repetition), "views": n_passive + len(chosen),
            "coverage": coverage, "path_length_m": length, "path_gap": path.gap, "seconds_path": seconds}
