"""One individual-plant case of the paper, end to end in the simulator.

scan -> coarse reconstruction (initial view + one NBV) -> registration of the previous session ->
inflation -> visibility on the planning surface -> set cover -> open TSP -> execution on the
current session's ground truth. The warm-up NBV is geometric (information gain on an occupancy map
of what was observed); it replaces the paper's learned PC-NBV network.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from tpvp.errors import ConfigError
from tpvp.inflation import InflationConfig, inflate
from tpvp.nbv import OccupancyMap, next_best_view
from tpvp.path.local import local_path_lengths, obstacle_radius, predicted_size
from tpvp.path.tsp import shortest_open_path
from tpvp.registration import EDConfig, register_embedded_deformation
from tpvp.scene import voxels
from tpvp.scene.normalise import normalise_plant
from tpvp.sensor.grid import build_grid, plant_grid
from tpvp.sensor.sensor import SensorConfig
from tpvp.setcover import SetCoverConfig, solve_set_cover
from tpvp.viewspace import INITIAL_VIEW_INDICES, load_view_space
from tpvp.visibility import coverage_ratio, oracle_voxels, visibility_matrix


@dataclass(frozen=True)
class SinglePlantConfig:
    """Paper's individual-plant setting (SPEC.md values as defaults)."""

    view_space: str = "hemisphere"
    table: bool | None = None  # None: a table for the hemisphere, none for the sphere
    largest_side: float = 0.24
    rotation_deg: float = 0.0
    initial_view: int = INITIAL_VIEW_INDICES["near_horizontal"]
    gt_resolution: float = 0.002
    cover_resolution: float = 0.004
    warm_up_views: int = 1
    inflation_enabled: bool = True
    registration: EDConfig = field(default_factory=EDConfig)
    inflation: InflationConfig = field(default_factory=InflationConfig)
    set_cover: SetCoverConfig = field(default_factory=SetCoverConfig)
    sensor: SensorConfig = field(default_factory=SensorConfig)

    @property
    def uses_table(self) -> bool:
        return self.view_space == "hemisphere" if self.table is None else bool(self.table)


@dataclass(frozen=True)
class Scene:
    """Normalised previous/current clouds, the current ground truth and its visibility."""

    previous: np.ndarray
    current: np.ndarray
    grid: object  # OccupancyGrid of the current ground truth (plant + table)
    views: np.ndarray  # (V, 3) candidate positions; every view looks at the origin
    truth_visibility: object  # csr (V, voxels): what each view observes on the ground truth
    oracle: np.ndarray


@dataclass(frozen=True)
class CaseResult:
    executed_views: list  # warm-up views, in order
    planned_views: list  # selected views in execution order (after the last warm-up view)
    coverage: float
    coverage_warm_up: float
    n_views: int  # warm-up views included, as in the paper
    path_length: float
    chamfer_before: float  # transferred model vs coarse reconstruction (m)
    chamfer_after: float
    set_cover: object
    tsp: object
    timings: dict
    clouds: dict  # coarse, warped, inflation, planning (for figures and recordings)
    obstacle: tuple  # (centre, radius) of the path's collision sphere

    def summary(self) -> dict:
        return {
            "views": self.n_views, "coverage": self.coverage, "path_length_m": self.path_length,
            "warm_up_views": len(self.executed_views), "planned_views": len(self.planned_views),
            "coverage_after_warm_up": self.coverage_warm_up,
            "chamfer_before_mm": 1e3 * self.chamfer_before, "chamfer_after_mm": 1e3 * self.chamfer_after,
            "set_cover_objective": self.set_cover.objective, "set_cover_bound": self.set_cover.bound,
            "set_cover_gap": self.set_cover.gap, "set_cover_optimal": self.set_cover.optimal,
            "set_cover_dropped_voxels": self.set_cover.n_dropped_infeasible,
            "tsp_optimal": self.tsp.optimal, "tsp_method": self.tsp.method,
            **{f"seconds_{k}": v for k, v in self.timings.items()},
        }


def build_scene(previous_points, current_points, config: SinglePlantConfig = SinglePlantConfig()) -> Scene:
    """Normalise both sessions in the current session's frame (the plant stays in place between
    sessions) and render the ground truth from every candidate view."""
    current = normalise_plant(current_points, config.largest_side, config.rotation_deg,
                              table=config.uses_table, table_resolution=config.gt_resolution)
    previous = current.transform(np.asarray(previous_points, dtype=np.float64))
    grid = plant_grid(current.points, current.table_points, config.gt_resolution)
    views = load_view_space(config.view_space)
    truth = visibility_matrix(grid, views, np.zeros(3), config.sensor)
    return Scene(previous, current.points, grid, views, truth, oracle_voxels(truth))


def _observed(scene: Scene, views) -> np.ndarray:
    ids = np.unique(np.concatenate([scene.truth_visibility[v].indices for v in views]))
    return ids


def run_case(scene: Scene, config: SinglePlantConfig = SinglePlantConfig(), progress=None) -> CaseResult:
    """Warm-up, transfer, plan and execute one case; ``progress(stage)`` is called per stage."""
    if not 0 <= config.initial_view < len(scene.views):
        raise ConfigError(f"initial_view {config.initial_view} is not one of the {len(scene.views)} views")
    say = progress or (lambda stage: None)
    timings = {}
    centre = np.zeros(3)
    views = scene.views

    t = time.perf_counter()
    say("warm-up NBV")
    executed = [config.initial_view]
    observations = [scene.grid.centres[scene.truth_visibility[config.initial_view].indices]]
    for _ in range(config.warm_up_views):
        occupancy = OccupancyMap.from_observations(centre, views[executed], observations,
                                                   look_ats=np.zeros((len(executed), 3)))
        nbv, _ = next_best_view(occupancy, views, np.zeros((len(views), 3)), executed=executed)
        executed.append(int(nbv))
        observations.append(scene.grid.centres[scene.truth_visibility[nbv].indices])
    coarse = np.concatenate(observations)  # duplicates kept, as the reference feeds registration
    timings["warm_up"] = time.perf_counter() - t

    t = time.perf_counter()
    say("registration")
    registration = register_embedded_deformation(scene.previous, coarse, config.registration)
    timings["registration"] = time.perf_counter() - t

    t = time.perf_counter()
    say("inflation")
    half_size = predicted_size(coarse, centre)
    if config.inflation_enabled:
        inflated = inflate(registration.warped, coarse, centre, half_size, config.inflation)
        planning_cloud, inflation_points = inflated.planning, inflated.inflation
    else:
        planning_cloud, inflation_points = registration.warped, np.zeros((0, 3))
    timings["inflation"] = time.perf_counter() - t

    t = time.perf_counter()
    say("visibility")
    planning_grid = build_grid(voxels.voxelise(planning_cloud, config.cover_resolution), config.cover_resolution)
    planning_visibility = visibility_matrix(planning_grid, views, np.zeros(3), config.sensor)
    timings["visibility"] = time.perf_counter() - t

    t = time.perf_counter()
    say("set cover")
    cover = solve_set_cover(planning_visibility, executed=executed, config=config.set_cover)
    timings["set_cover"] = time.perf_counter() - t

    t = time.perf_counter()
    say("path")
    radius = obstacle_radius(coarse, centre)
    stops = [executed[-1], *cover.selected]
    distance = local_path_lengths(views[stops], centre, radius)
    tsp = shortest_open_path(distance, start=0)
    planned = [stops[i] for i in tsp.order[1:]]
    warm_up_path = sum(local_path_lengths(views[[a, b]], centre, radius)[0, 1]
                       for a, b in zip(executed[:-1], executed[1:]))
    timings["path"] = time.perf_counter() - t
    timings["planning"] = timings["inflation"] + timings["visibility"] + timings["set_cover"] + timings["path"]

    covered = _observed(scene, executed + planned)
    return CaseResult(
        executed_views=executed, planned_views=planned,
        coverage=coverage_ratio(covered, scene.oracle),
        coverage_warm_up=coverage_ratio(_observed(scene, executed), scene.oracle),
        n_views=len(executed) + len(planned), path_length=float(warm_up_path + tsp.length),
        chamfer_before=registration.chamfer_before, chamfer_after=registration.chamfer_after,
        set_cover=cover, tsp=tsp, timings=timings,
        clouds={"coarse": np.unique(coarse, axis=0), "previous": scene.previous,
                "warped": registration.warped, "inflation": inflation_points, "planning": planning_cloud},
        obstacle=(centre, radius),
    )


def write_case_outputs(folder, scene: Scene, result: CaseResult, config: SinglePlantConfig,
                       name: str = "case") -> dict:
    """Results (JSON + CSV), the robot plan (CSV + JSON), PNG figures and a rerun ``.rrd``."""
    import json
    from pathlib import Path

    import pandas as pd

    from tpvp.io import atomic_write_text
    from tpvp.io.plan import plan_table, write_plan
    from tpvp.path.local import local_path_points
    from tpvp.viz import plot_coverage, plot_plan, write_recording

    folder = Path(folder)
    order = result.executed_views + result.planned_views
    roles = ["initial"] + ["warm-up NBV"] * (len(result.executed_views) - 1) + ["planned"] * len(result.planned_views)
    table = plan_table(scene.views[order], np.zeros(3), roles)
    table.insert(1, "view_index", order)
    frame = ("plant frame: current session scaled to a largest side of "
             f"{config.largest_side} m, rotated {config.rotation_deg} deg about +Z, bounding-box centre at the origin")
    plan_csv, plan_json = write_plan(folder, table, frame)
    summary = {"name": name, "view_space": config.view_space, "initial_view": config.initial_view,
               "oracle_voxels": int(len(scene.oracle)), **result.summary()}
    atomic_write_text(folder / "results.json", json.dumps(summary, indent=2, default=float) + "\n")
    atomic_write_text(folder / "results.csv", pd.DataFrame([summary]).to_csv(index=False))

    centre, radius = result.obstacle
    positions = scene.views[order]
    polyline = np.concatenate([local_path_points(a, b, centre, radius) for a, b in zip(positions[:-1], positions[1:])]) \
        if len(positions) > 1 else positions
    plan_png = plot_plan(folder / "plan.png", scene.current, scene.views, scene.views[result.executed_views],
                         scene.views[result.planned_views], polyline,
                         f"{name}: {result.n_views} views, {100 * result.coverage:.2f}% coverage, "
                         f"{result.path_length:.2f} m path")
    covered = np.zeros(scene.grid.size, bool)
    covered[_observed(scene, order)] = True
    observable = np.zeros(scene.grid.size, bool)
    observable[scene.oracle] = True
    plant = scene.grid.countable
    coverage_png = plot_coverage(folder / "coverage.png", scene.grid.centres[plant], covered[plant],
                                 observable[plant], f"{name}: covered vs missed ground-truth voxels (2 mm)")
    rrd = write_recording(
        folder / "recording.rrd",
        clouds={"current_truth": (scene.current, (120, 120, 120)), "previous": (result.clouds["previous"], (220, 60, 60)),
                "coarse": (result.clouds["coarse"], (40, 90, 220)), "transferred": (result.clouds["warped"], (230, 140, 30)),
                "inflation": (result.clouds["inflation"], (40, 180, 60))},
        cameras={"warm_up_views": (scene.views[result.executed_views], np.zeros(3)),
                 "planned_views": (scene.views[result.planned_views], np.zeros(3))},
        paths={"global_path": polyline})
    return {"results": folder / "results.json", "plan": plan_csv, "plan_json": plan_json,
            "figures": [plan_png, coverage_png], "recording": rrd}
