"""A season, not a session: the sessions of one plant chained, each planned from a prior.

Session 1 plans day 2 from day 1's full scan. From session 2 on, each arm plans day k from its own
prior: ``truth``, the previous day's ground-truth scan (the paper's protocol), ``own``, what the
previous session reconstructed from its own executed views (the voxels they saw of that day's
plant, as ``tpvp session export`` writes it): the closed loop a monitoring robot runs, or ``none``:
no prior, the geometric NBV until its true coverage reaches the coverage target (a stopping rule
on the ground truth: a lower bound for a robot without a prior). Every
session is measured on today's ground truth: views, true coverage, path, the Chamfer distance of
what the session reconstructed to today's plant, the registration residual, and the share of
today's plant the registered prior held nothing near.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from tpvp.config import PlantConfig, make_config, with_overrides
from tpvp.errors import ConfigError
from tpvp.experiments import runner
from tpvp.experiments.results import mean_std
from tpvp.experiments.runner import Experiment
from tpvp.experiments.baselines import nbv_curve
from tpvp.experiments.single_plant import build_scene, run_case
from tpvp.metrics import chamfer_distance
from tpvp.registry import Registry
from tpvp.scene import voxels
from tpvp.scene.simulator import scan_points
from tpvp.synthetic.plants import generate_growth_series
from tpvp.visibility import covered_voxels
from tpvp.viz.experiments import plot_season

ARMS = ("truth", "own", "none")
#: The most views the ``none`` arm's sequential NBV may take to reach the coverage target.
NONE_MAX_VIEWS = 40
SEASON_ARMS = Registry("season arm")
#: What ``tpvp experiments season`` runs: the coverage target, generated plants and their sessions.
COVERAGE_TARGET = 0.98
SPECIES = ("tomato", "maize")
SESSIONS = 6
QUICK = {"species": ("tomato",), "seeds": (0,), "sessions": 3}
SEASON_COLUMNS = ("session", "arm", "views", "coverage", "path_length_m", "chamfer_fused_mm",
                  "registration_chamfer_mm", "prior_missing", "prior_points")


def reconstruction(scene, views) -> np.ndarray:
    """What ``views`` saw of today's plant: the centres of the ground-truth voxels they see
    (planning frame), as a session's fused captures are."""
    return scene.grid.centres[covered_voxels(scene.truth_visibility, list(views))]


def prior_missing(scene, warped: np.ndarray, voxel: float) -> float:
    """The share of today's plant voxels with no point of the registered prior in them or in a
    voxel next to them (26-neighbourhood, ``voxel`` metres)."""
    plant = scene.grid.centres[scene.grid.countable]
    if len(plant) == 0:
        return float("nan")
    held = voxels.encode_keys(voxels.voxelise(warped, voxel))
    keys = voxels.voxel_keys(plant, voxel)
    found = np.zeros(len(plant), bool)
    for offset in np.stack(np.meshgrid(*[np.arange(-1, 2)] * 3, indexing="ij"), axis=-1).reshape(-1, 3):
        found |= np.isin(voxels.encode_keys(keys + offset), held)
    return float(1.0 - found.mean())


def _without_prior(scene, config: PlantConfig):
    """The ``none`` arm: the geometric NBV from the initial view until its true coverage reaches the
    coverage target (or :data:`NONE_MAX_VIEWS`); (views, coverage, path, executed views)."""
    curve = nbv_curve(scene, with_overrides(config, {"nbv.method": "geometric"}), NONE_MAX_VIEWS)
    reached = curve[curve["coverage"] >= config.selection.coverage_target - 1e-12]
    last = reached.iloc[0] if len(reached) else curve.iloc[-1]
    steps = int(last["views"])
    return steps, float(last["coverage"]), float(last["path_length"]), curve["view"].iloc[:steps].astype(int).tolist()


def run_season(series, config: PlantConfig = PlantConfig(), arms=ARMS, name: str = "plant") -> pd.DataFrame:
    """One row per session (2 .. n: the day planned) and arm. ``series``: the plant's scans in
    order (points, metres), day 1 first."""
    series = [np.asarray(points, dtype=np.float64) for points in series]
    if len(series) < 2:
        raise ConfigError(f"{name}: a season needs at least 2 scans, got {len(series)}")
    unknown = [arm for arm in arms if arm not in ARMS]
    if unknown:
        raise ConfigError(f"unknown season arm {unknown[0]!r}; choose from {', '.join(ARMS)}")
    rows, own = [], series[0]  # session 1 starts from day 1's full scan
    for day in range(1, len(series)):
        next_own = own
        for arm in arms:
            prior = series[day - 1] if arm in ("truth", "none") else own
            scene = build_scene(prior, series[day], config,
                                names=(f"{name} day {day} ({arm} prior)", f"{name} day {day + 1}"))
            per_mm = 1e3 / scene.scan_scale  # planning-frame metres -> the scans' millimetres
            if arm == "none":
                views, coverage, path_length, order = _without_prior(scene, config)
                registration = missing = float("nan")
            else:
                result = run_case(scene, config)
                views, coverage, path_length, order = result.n_views, result.coverage, result.path_length, result.order
                registration = per_mm * result.chamfer_after
                missing = prior_missing(scene, result.clouds["warped"], config.gt_resolution)
            fused = reconstruction(scene, order)
            rows.append({"session": day + 1, "arm": arm, "views": views, "coverage": coverage,
                         "path_length_m": path_length, "chamfer_fused_mm": per_mm * chamfer_distance(fused, scene.current),
                         "registration_chamfer_mm": registration, "prior_missing": missing,
                         "prior_points": 0 if arm == "none" else len(prior)})
            if arm == "own":
                next_own = scan_points(scene.plant_from_scan, fused)
        own = next_own
    return pd.DataFrame(rows, columns=list(SEASON_COLUMNS))


@dataclass(frozen=True)
class SeasonCase:
    """One generated plant's season: ``sessions`` scans ``days`` apart, planned for ``coverage_target``."""

    species: str
    seed: int
    sessions: int = SESSIONS
    days: float = 2.0
    view_space: str = "hemisphere"
    coverage_target: float = COVERAGE_TARGET

    def config(self, base: PlantConfig) -> PlantConfig:
        return with_overrides(base, {"view_space": self.view_space, "selection.coverage_target": self.coverage_target})

    def labels(self) -> dict:
        return {"plant": f"{self.species}-generated-{self.seed}", "species": self.species, "seed": self.seed,
                "view_space": self.view_space, "coverage_target": self.coverage_target}


def season_cases(quick: bool = False, species=SPECIES, seeds=(0,), sessions: int = SESSIONS,
                 view_spaces=("hemisphere",), coverage_target: float = COVERAGE_TARGET) -> list[SeasonCase]:
    if quick:
        species, seeds, sessions = QUICK["species"], QUICK["seeds"], QUICK["sessions"]
    return [SeasonCase(s, int(seed), int(sessions), view_space=v, coverage_target=float(coverage_target))
            for v in view_spaces for s in species for seed in seeds]


def _series(case: SeasonCase, case_config, cache_dir=None) -> list:
    return [sample.points for sample in generate_growth_series(case.species, case.seed, case.sessions, case.days)]


def _arm(name: str):
    def run(series, config):
        return run_season(series, config, arms=(name,)).drop(columns=["arm"]).to_dict("records")
    return run


for _name, _help in (("truth", "each session from the previous day's ground-truth scan (the paper's protocol)"),
                     ("own", "each session from what the previous session's own views reconstructed (closed loop)"),
                     ("none", "no prior: the geometric NBV until it reaches the coverage target")):
    SEASON_ARMS.register(_name, _help, default=True)(_arm(_name))


def tables(raw: pd.DataFrame) -> dict:
    """Per session and arm (means over the plants), and per season: total views, the lowest
    coverage of any session, and how far the fused model's Chamfer distance drifted (last session
    minus the first)."""
    rows = raw.rename(columns={"method": "arm"})
    per_session = mean_std(rows, ["view_space", "session", "arm"],
                           columns=("views", "coverage", "path_length_m", "chamfer_fused_mm",
                                    "registration_chamfer_mm", "prior_missing"))
    season = rows.groupby(["view_space", "plant", "arm"], sort=False).agg(
        sessions=("session", "size"), total_views=("views", "sum"), lowest_coverage=("coverage", "min"),
        chamfer_first_mm=("chamfer_fused_mm", "first"), chamfer_last_mm=("chamfer_fused_mm", "last"),
        path_length_m=("path_length_m", "sum")).reset_index()
    season["lowest_coverage"] *= 100
    season["chamfer_drift_mm"] = season["chamfer_last_mm"] - season["chamfer_first_mm"]
    season = season.round({"lowest_coverage": 2, "chamfer_first_mm": 3, "chamfer_last_mm": 3, "chamfer_drift_mm": 3,
                           "path_length_m": 2})
    return {"season_per_session": per_session, "season_totals": season}


def _figures(folder, raw: pd.DataFrame, written: dict, config) -> None:
    plot_season(folder / "figures" / "season.png", written["season_per_session"])


SEASON_EXPERIMENTS = Experiment("season experiments", SEASON_ARMS, _series,
                                order=("view_space", "plant", "method", "session"), tables=tables,
                                figures=_figures, reference=f"{__name__}:SEASON_EXPERIMENTS")


def run_season_experiments(cases, arms=ARMS, config: PlantConfig | None = None, cache_dir=None, workers: int = 1,
                           progress: bool = True) -> pd.DataFrame:
    """Every (plant, arm) season, cached and resumable like the other experiments; the raw table."""
    return runner.run_experiments(SEASON_EXPERIMENTS, cases, arms, config or make_config("plant"), cache_dir,
                                  workers, progress)
