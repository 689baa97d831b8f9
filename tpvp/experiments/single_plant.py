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

from tpvp.config import PlantConfig
from tpvp.errors import PointCloudError, checked_cloud
from tpvp.inflation import inflate
from tpvp.nbv.methods import NbvContext, make_nbv
from tpvp.path.local import local_path_lengths, obstacle_radius, predicted_size
from tpvp.path.tsp import shortest_open_path
from tpvp.registration.methods import register
from tpvp.scene import voxels
from tpvp.scene.grid import build_grid, plant_grid
from tpvp.scene.normalise import check_session_pair, normalise_plant, up_rotation
from tpvp.setcover.methods import SelectionProblem, select_views
from tpvp.viewspace import get_view_space
from tpvp.visibility import coverage_ratio, covered_voxels, oracle_voxels, visibility_matrix

NATIVE_RADIUS = 0.4  # m around the real plant when scale = native and no radius is given


@dataclass(frozen=True, eq=False)
class Scene:
    """Both sessions in the planning frame, the current ground truth and what each view sees.

    The planning frame is the normalised plant frame (docs/single_plant.md#normalisation);
    ``plant_from_scan`` (4x4, scale included) maps the scan's metric frame into it. ``view_space``
    and ``sensor`` are those of the planning frame (scaled when planning at the plant's true size).
    """

    previous: np.ndarray
    current: np.ndarray
    grid: object  # OccupancyGrid of the current ground truth (plant + table)
    view_space: object  # tpvp.viewspace.ViewSpace
    sensor: object  # SensorConfig in the planning frame
    truth_visibility: object  # csr (V, voxels): what each view observes on the ground truth
    oracle: np.ndarray
    plant_from_scan: np.ndarray
    table_points: np.ndarray
    names: tuple = ("previous-session scan", "current-session scan")
    reduction: dict | None = None  # points in and used per scan, reduction voxel

    @property
    def views(self) -> np.ndarray:
        return self.view_space.positions

    @property
    def scan_scale(self) -> float:
        """Planning-frame metres per scan metre."""
        return float(np.cbrt(np.linalg.det(self.plant_from_scan[:3, :3])))


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


def build_scene(previous_points, current_points, config: PlantConfig = PlantConfig(),
                names=("previous-session scan", "current-session scan")) -> Scene:
    """Bring both sessions into the planning frame defined by the current session (the plant stays
    in place between sessions) and render the ground truth from every candidate view.

    ``names`` (e.g. the files) name the scans in errors. Scans of more than
    ``scene.reduce_above`` points are reduced to voxel centroids at ``scene.reduce_resolution``;
    the ground truth is built from every point of the current scan, so it does not change."""
    up = up_rotation(config.scene.up_axis)
    current_scan, previous_scan = (checked_cloud(points, name) for points, name in
                                   ((current_points, names[1]), (previous_points, names[0])))
    if config.scene.up_axis != "+z":
        current_scan, previous_scan = current_scan @ up.T, previous_scan @ up.T
    check_session_pair(previous_scan, current_scan, names)
    space = get_view_space(config.view_space)
    current = normalise_plant(current_scan, config.scene.largest_side, config.scene.rotation_deg,
                              centre=config.scene.centre, table=config.uses_table, name=names[1],
                              table_size=config.scene.table_size, table_resolution=config.scene.table_resolution)
    sensor = config.sensor
    if config.scene.scale == "native":
        # The plant keeps its size: the view sphere and the sensor range are real metres, so in the
        # planning frame they scale with the plant like every resolution does.
        space = space.with_radius((config.scene.radius or NATIVE_RADIUS) * current.scale)
        sensor = replace(sensor, max_range=sensor.max_range * current.scale)
    elif config.scene.radius is not None:
        space = space.with_radius(config.scene.radius)
    grid = plant_grid(current.points, current.table_points, config.gt_resolution)
    previous = current.transform(previous_scan)
    del previous_scan, current_scan
    reduction = {"resolution_m": config.scene.reduce_resolution, "previous_points": len(previous),
                 "current_points": len(current.points)}
    # Centroids lie in their points' voxels, so the reduction keeps the ground-truth voxel sets.
    previous, current_points = (voxels.voxel_centroids(p, config.scene.reduce_resolution)
                                if len(p) > config.scene.reduce_above else p
                                for p in (previous, current.points))
    reduction.update(previous_points_used=len(previous), current_points_used=len(current_points))
    for name, points, count in ((names[0], previous, None), (names[1], current_points, int(grid.countable.sum()))):
        count = len(voxels.voxelise(points, config.gt_resolution)) if count is None else count
        if count < config.scene.min_plant_voxels:
            raise PointCloudError(
                f"{name}: only {count} occupied {1e3 * config.gt_resolution:g} mm voxels once the plant is "
                f"scaled to a {config.scene.largest_side:g} m largest side ({len(points)} points); a plant scan "
                f"has at least {config.scene.min_plant_voxels} - is this the right file?")
    truth = visibility_matrix(grid, space.positions, space.look_ats, sensor)
    plant_from_scan = current.matrix
    plant_from_scan[:3, :3] = plant_from_scan[:3, :3] @ up
    return Scene(previous, current_points, grid, space, sensor, truth, oracle_voxels(truth), plant_from_scan,
                 current.table_points, names, reduction)


def observation(scene: Scene, view: int) -> np.ndarray:
    """What ``view`` observes of the current plant: the centres of the ground-truth voxels it sees."""
    return scene.grid.centres[scene.truth_visibility[view].indices]


def added_coverage(scene, executed) -> np.ndarray:
    """Per view: the oracle voxels it sees that none of ``executed`` sees (``(V,)`` int)."""
    from scipy import sparse

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


def warm_up(scene: Scene, config: PlantConfig):
    """The initial view and ``config.nbv.warm_up_views`` NBVs executed: the NBV method, holding
    the executed views and their observations."""
    space = scene.view_space
    initial = space.view_index(config.initial_view)
    nbv = make_nbv(NbvContext(space, np.zeros(3), scene.sensor, config.nbv, prior=scene.previous))
    nbv.integrate(initial, observation(scene, initial))
    for _ in range(config.nbv.warm_up_views):
        choice = nbv.next_view()
        nbv.integrate(choice.view, observation(scene, choice.view))
    return nbv


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


def transfer(scene: Scene, config: PlantConfig = PlantConfig(), progress=None) -> Transfer:
    """Initial view, warm-up NBVs and registration of the previous session onto what they saw."""
    say = progress or (lambda stage: None)
    timings = {}
    t = time.perf_counter()
    say("warm-up NBV")
    nbv = warm_up(scene, config)
    coarse = np.concatenate(nbv.observations)
    timings["warm_up"] = time.perf_counter() - t

    t = time.perf_counter()
    say("registration")
    alignment = register(scene.previous, coarse, config.registration)
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
             transferred: Transfer | None = None) -> CaseResult:
    """Warm-up, transfer, plan and execute one case; ``progress(stage)`` is called per stage.
    ``transferred``: the :func:`transfer` of this scene and configuration when already computed
    (methods that differ only after registration share it)."""
    say = progress or (lambda stage: None)
    space = scene.view_space
    centre = np.zeros(3)
    transferred = transferred or transfer(scene, config, progress)
    nbv, executed, coarse, alignment = (transferred.nbv, transferred.executed, transferred.coarse,
                                        transferred.alignment)
    timings = dict(transferred.timings)
    warnings = list(transferred.warnings)

    t = time.perf_counter()
    say("inflation")
    inflated = inflate(alignment.warped, coarse, centre, predicted_size(coarse, centre), config.inflation)
    timings["inflation"] = time.perf_counter() - t

    t = time.perf_counter()
    say("visibility")
    planning_grid, visibility = planning_visibility(scene, inflated.planning, config.selection.cover_resolution)
    timings["visibility"] = time.perf_counter() - t

    t = time.perf_counter()
    say("view selection")
    problem = SelectionProblem(visibility, tuple(executed), space, planning_grid.centres,
                               config.selection.planning_target(config.view_space), nbv=nbv)
    selection = select_views(problem, config.selection)
    timings["selection"] = time.perf_counter() - t

    t = time.perf_counter()
    say("path")
    planned, path_length, tsp, radius = path_through(space, executed, selection.selected, coarse, config)
    timings["path"] = time.perf_counter() - t
    timings["planning"] = sum(timings[k] for k in ("inflation", "visibility", "selection", "path"))

    return CaseResult(
        executed_views=executed, planned_views=planned,
        coverage=coverage_ratio(covered_voxels(scene.truth_visibility, executed + planned), scene.oracle),
        coverage_warm_up=coverage_ratio(covered_voxels(scene.truth_visibility, executed), scene.oracle),
        n_views=len(executed) + len(planned), path_length=path_length,
        chamfer_before=alignment.chamfer_before, chamfer_after=alignment.chamfer_after,
        selection=selection, tsp=tsp, timings=timings,
        clouds={"coarse": np.unique(coarse, axis=0), "previous": scene.previous,
                "warped": alignment.warped, "inflation": inflated.inflation, "planning": inflated.planning},
        obstacle=(centre, radius), warnings=warnings, planning_target=problem.coverage_target,
    )


def path_through(space, executed, selected, coarse, config: PlantConfig):
    """The executed views' path, then the shortest open path from the last one through ``selected``;
    the obstacle sphere is sized on the coarse reconstruction. Returns (planned views in order,
    whole path length, the TSP result, obstacle radius)."""
    centre = np.zeros(3)
    radius = obstacle_radius(coarse, centre)
    stops = [executed[-1], *selected]
    tsp = shortest_open_path(local_path_lengths(space.positions[stops], centre, radius), start=0, config=config.path)
    planned = [int(stops[i]) for i in tsp.order[1:]]
    warm_up_path = float(np.trace(local_path_lengths(space.positions[executed], centre, radius), offset=1)) \
        if len(executed) > 1 else 0.0
    return planned, warm_up_path + tsp.length, tsp, radius


def _registration_warnings(scene: Scene, alignment, config: PlantConfig) -> list:
    """A registration that ends far from the coarse scan for the plant's size means the two scans
    are hardly two sessions of one plant; said in the scans' own units."""
    size = config.scene.largest_side
    fraction = alignment.chamfer_after / size
    if fraction <= config.registration.warn_chamfer_fraction:
        return []
    per_scan = 1e3 / scene.scan_scale
    return [f"registration of {scene.names[0]} onto the coarse scan of {scene.names[1]} ends at "
            f"{alignment.chamfer_after * per_scan:.3g} mm Chamfer ({100 * fraction:.1f} % of the plant's "
            f"{size * per_scan:.3g} mm; a matching pair of sessions ends below "
            f"{100 * config.registration.warn_chamfer_fraction:g} %): are these two sessions of the same "
            f"plant? The plan relies on the aligned previous session"]
