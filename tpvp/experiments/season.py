"""A season, not a session: the sessions of one plant chained, each planned from a prior.

Session 1 plans day 2 from day 1's full scan. From session 2 on, each arm plans day k from its own
prior: ``truth``, the previous day's ground-truth scan (the paper's protocol), ``own``, what the
previous session reconstructed from its own executed views: the model fused from their depth images
through the configured sensor (``sensor.noise``) by the code that fuses a phone's capture
(:func:`tpvp.simulate.depth_captures.fused_captures`): the closed loop a monitoring robot runs, or
``none``: no prior, the geometric NBV until its true coverage reaches the coverage target (a
stopping rule on the ground truth: a lower bound for a robot without a prior). Each session plans
in the frame a robot knows (``scene.frame = previous``: from its prior and the first capture).
Every session is measured on today's ground truth: views, true coverage, path, the Chamfer distance
of the model fused from its captures to today's plant, the registration residual, and the share of
today's plant the registered prior held nothing near.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from tpvp.config import PlantConfig
from tpvp.config_loading import make_config, with_overrides
from tpvp.errors import ConfigError, InputFileError
from tpvp.experiments import runner
from tpvp.experiments.results import mean_std
from tpvp.experiments.runner import Experiment
from tpvp.experiments.baselines import nbv_curve
from tpvp.simulate.greenhouse import build_row_scene, execute, observed_points, run_row_case
from tpvp.experiments.plants import dataset_table
from tpvp.io import read_point_cloud
from tpvp.scene.frame import scan_points
from tpvp.simulate.depth_captures import fused_captures
from tpvp.simulate.single_plant import build_scene, run_case
from tpvp.metrics import chamfer_distance
from tpvp.nbv.blockwise import blockwise_nbv
from tpvp.registry import Registry
from tpvp.scene import voxels
from tpvp.scene.boxes import room_config
from tpvp.setcover.miss_model import plan_summary
from tpvp.synthetic.greenhouse import generate_row_sessions
from tpvp.synthetic.plants import generate_growth_series
from tpvp.synthetic.scan import reference_points
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
SEEDS = (0, 1, 2)
VIEW_SPACES = ("hemisphere", "sphere")
REPLAN_AFTER = (0, 1)  # plan once; re-plan after every planned view (as the re-planning rule was calibrated)
FRAME = "previous"  # scene.frame of every session: the one a robot knows (its prior and first capture)
#: Whether the own prior also keeps the registered prior where today's views did not look again
#: (season_sessions). Off: on calibration seeds 10-11 it lowered the phone's hemisphere sessions
#: (benchmarks/results/season_world_calibrate.md).
CARRY_UNSEEN = False
QUICK = {"species": ("tomato",), "seeds": (0,), "sessions": 3}
SEASON_COLUMNS = ("session", "arm", "views", "coverage", "path_length_m", "chamfer_fused_mm",
                  "registration_chamfer_mm", "prior_missing", "prior_points", "predicted_coverage",
                  "predicted_coverage_lower")


def held_near(points: np.ndarray, prior: np.ndarray, voxel: float) -> np.ndarray:
    """Which ``points`` have a point of ``prior`` in their voxel or a voxel next to it
    (26-neighbourhood, ``voxel`` metres)."""
    near = voxels.dilate_keys(voxels.voxelise(prior, voxel), np.sqrt(3))  # the voxel and its 26 neighbours
    return voxels.contains_keys(near, voxels.voxel_keys(points, voxel))


def prior_missing(scene, warped: np.ndarray, voxel: float) -> float:
    """The share of today's plant voxels with no point of the registered prior in them or in a
    voxel next to them (:func:`held_near`)."""
    plant = scene.grid.centres[scene.grid.countable]
    if len(plant) == 0:
        return float("nan")
    return float(1.0 - held_near(plant, warped, voxel).mean())


def _without_prior(scene, config: PlantConfig):
    """The ``none`` arm: the geometric NBV from the initial view until its true coverage reaches the
    coverage target (or :data:`NONE_MAX_VIEWS`); (views, coverage, path, executed views)."""
    curve = nbv_curve(scene, with_overrides(config, {"nbv.method": "geometric"}), NONE_MAX_VIEWS)
    reached = curve[curve["coverage"] >= config.selection.coverage_target - 1e-12]
    last = reached.iloc[0] if len(reached) else curve.iloc[-1]
    steps = int(last["views"])
    return steps, float(last["coverage"]), float(last["path_length"]), curve["view"].iloc[:steps].astype(int).tolist()


@dataclass(frozen=True, eq=False)
class SeasonSession:
    """One session of one arm: today's case (``scene``: the arm's prior registered against today's
    ground truth), the prior it planned from (scan frame), the views it executed, the model fused
    from their captures (``fused``, planning frame), the registered prior (``warped``, planning frame;
    None for ``none``) and the session's row of :data:`SEASON_COLUMNS`."""

    scene: object
    prior: np.ndarray
    order: list
    fused: np.ndarray
    warped: np.ndarray | None
    row: dict

    def missed(self, voxel: float) -> dict:
        """Today's plant voxel centres (planning frame) by what became of them: ``seen``, missed
        where the registered prior held nothing near (``missed_not_in_prior``: growth or a hole of
        the prior), missed though the prior held them (``missed_in_prior``: left by the plan, or
        seen only from views it did not take) and ``unseeable`` (no candidate view sees them: not
        counted by the coverage)."""
        scene = self.scene
        plant = scene.grid.countable_ids
        centres = scene.grid.centres[plant]
        seen = np.isin(plant, covered_voxels(scene.truth_visibility, list(self.order)))
        seeable = np.isin(plant, scene.oracle)
        held = (held_near(centres, self.warped, voxel) if self.warped is not None
                else np.zeros(len(plant), bool))
        missed = seeable & ~seen
        return {"seen": centres[seen], "missed_in_prior": centres[missed & held],
                "missed_not_in_prior": centres[missed & ~held], "unseeable": centres[~seeable]}


def chained_sessions(series, arms, name: str, session):
    """Every session (2 .. n: the day planned) of every arm, in order: ``session(prior, today,
    day, arm)`` plans and measures one, returning (its :class:`SeasonSession`, what it saw of
    today: the next ``own`` prior). ``truth`` and ``none`` plan from the previous day's scan,
    ``own`` from what its previous session saw; session 2 starts every arm from day 1's scan."""
    series = [np.asarray(points, dtype=np.float64) for points in series]
    if len(series) < 2:
        raise ConfigError(f"{name}: a season needs at least 2 scans, got {len(series)}")
    unknown = [arm for arm in arms if arm not in ARMS]
    if unknown:
        raise ConfigError(f"unknown season arm {unknown[0]!r}; choose from {', '.join(ARMS)}")
    own = series[0]
    for day in range(1, len(series)):
        next_own = own
        for arm in arms:
            done, seen = session(own if arm == "own" else series[day - 1], series[day], day, arm)
            yield done
            if arm == "own":
                next_own = seen
        own = next_own


def season_sessions(series, config: PlantConfig = PlantConfig(), arms=ARMS, name: str = "plant",
                    carry_unseen: bool = CARRY_UNSEEN):
    """A plant's sessions per arm (:func:`chained_sessions`). ``series``: its scans in order
    (points, metres), day 1 first. ``carry_unseen``: the next ``own`` prior also keeps the points
    of the registered prior that today's fused model holds nothing near (:func:`held_near`): a
    model updated where the views looked, kept where they did not."""
    def session(prior, today, day, arm):
        scene = build_scene(prior, today, config, names=(f"{name} day {day} ({arm} prior)", f"{name} day {day + 1}"))
        per_mm = 1e3 / scene.scan_scale  # planning-frame metres -> the scans' millimetres
        warped = None
        predicted = (float("nan"), float("nan"))  # the plan's own expectation (the per-case miss model)
        if arm == "none":
            views, coverage, path_length, order = _without_prior(scene, config)
            registration = missing = float("nan")
        else:
            result = run_case(scene, config)
            views, coverage, path_length, order = result.n_views, result.coverage, result.path_length, result.order
            predicted = (result.predicted_coverage, result.predicted_coverage_lower)
            registration = per_mm * result.chamfer_after
            warped = result.clouds["warped"]
            missing = prior_missing(scene, warped, config.gt_resolution)
        fused = fused_captures(scene, order)  # scan frame: the next own prior
        planning = fused @ scene.plant_from_scan[:3, :3].T + scene.plant_from_scan[:3, 3]
        if carry_unseen and warped is not None:
            unseen = warped[~held_near(warped, planning, config.gt_resolution)]
            fused = np.concatenate([fused, scan_points(scene.plant_from_scan, unseen)])
        row = {"session": day + 1, "arm": arm, "views": views, "coverage": coverage,
               "path_length_m": path_length, "chamfer_fused_mm": per_mm * chamfer_distance(planning, scene.current),
               "registration_chamfer_mm": registration, "prior_missing": missing,
               "prior_points": 0 if arm == "none" else len(prior), "predicted_coverage": predicted[0],
               "predicted_coverage_lower": predicted[1]}
        return SeasonSession(scene, prior, list(order), planning, warped, row), fused

    return chained_sessions(series, arms, name, session)


def run_season(series, config: PlantConfig = PlantConfig(), arms=ARMS, name: str = "plant",
               carry_unseen: bool = CARRY_UNSEEN) -> pd.DataFrame:
    """One row per session (2 .. n: the day planned) and arm (:func:`season_sessions`)."""
    return pd.DataFrame([session.row for session in season_sessions(series, config, arms, name, carry_unseen)],
                        columns=list(SEASON_COLUMNS))


@dataclass(frozen=True)
class SeasonCase:
    """One generated plant's season: ``sessions`` scans ``days`` apart, planned for ``coverage_target``."""

    species: str
    seed: int
    sessions: int = SESSIONS
    days: float = 2.0
    view_space: str = "hemisphere"
    coverage_target: float = COVERAGE_TARGET
    replan_after: int = 0  # selection.replan_after of every session's plan (the none arm has no plan)
    carry_unseen: bool = CARRY_UNSEEN  # the own prior keeps the registered prior where today's views saw nothing
    frame: str = FRAME  # scene.frame: from what the robot knows (its prior), or "current" (today's scan)
    files: tuple = ()  # a dataset plant's scans, day by day (metric point clouds); empty: generated
    plant: str = ""  # the dataset's plant name

    def config(self, base: PlantConfig) -> PlantConfig:
        return with_overrides(base, {"view_space": self.view_space, "selection.coverage_target": self.coverage_target,
                                     "selection.replan_after": self.replan_after, "scene.frame": self.frame})

    def labels(self) -> dict:
        return {"plant": self.plant or f"{self.species}-generated-{self.seed}", "species": self.species,
                "seed": self.seed, "view_space": self.view_space, "coverage_target": self.coverage_target,
                "replan_after": self.replan_after, "frame": self.frame, "carry_unseen": self.carry_unseen}


def season_cases(quick: bool = False, species=SPECIES, seeds=SEEDS, sessions: int = SESSIONS,
                 view_spaces=VIEW_SPACES, coverage_target: float = COVERAGE_TARGET,
                 replan_after=REPLAN_AFTER, frame: str = FRAME, carry_unseen: bool = CARRY_UNSEEN) -> list[SeasonCase]:
    """The full protocol's seasons (by default), or the quick ones (one tomato, 3 sessions, each
    view space and re-planning asked)."""
    if quick:
        species, seeds, sessions = QUICK["species"], QUICK["seeds"], QUICK["sessions"]
    return [SeasonCase(s, int(seed), int(sessions), view_space=v, coverage_target=float(coverage_target),
                       replan_after=int(k), frame=frame, carry_unseen=carry_unseen)
            for k in replan_after for v in view_spaces for s in species for seed in seeds]


def dataset_season_cases(folder, plants=None, quick: bool = False, view_spaces=VIEW_SPACES,
                         coverage_target: float = COVERAGE_TARGET, replan_after=REPLAN_AFTER,
                         frame: str = FRAME) -> list[SeasonCase]:
    """Every plant of a prepared dataset (``python -m data_tools pheno4d prepare``: ``pairs.csv``
    and its metric clouds), its scans in date order, one season per plant (or only ``plants``;
    ``quick``: the first plant's first three scans)."""
    table = dataset_table(folder, plants)
    if table.empty:
        raise ConfigError(f"{Path(folder) / 'pairs.csv'}: no plant named {', '.join(map(str, plants))}")
    cases = []
    for plant, rows in table.groupby("plant", sort=True):
        rows = rows.sort_values("previous_date")
        files = [*rows["previous_file"], rows["current_file"].iloc[-1]]
        days = list(zip(rows["current_date"].iloc[:-1], rows["previous_date"].iloc[1:]))
        if any(str(a) != str(b) for a, b in days):
            raise InputFileError(f"{Path(folder) / 'pairs.csv'}: {plant}'s pairs do not chain day by day "
                                 f"({', '.join(f'{a} then {b}' for a, b in days if str(a) != str(b))})")
        files = tuple(str(Path(folder) / f) for f in files)[:3 if quick else None]
        cases += [SeasonCase(str(rows["species"].iloc[0]).lower(), 0, len(files), view_space=v,
                             coverage_target=float(coverage_target), replan_after=int(k), files=files, plant=str(plant),
                             frame=frame)
                  for k in replan_after for v in view_spaces]
        if quick:
            break
    return cases


@dataclass(frozen=True)
class _PlantSeries:
    scans: list
    carry_unseen: bool


def _series(case: SeasonCase, case_config, cache_dir=None) -> _PlantSeries:
    if case.files:
        scans = [read_point_cloud(Path(f), units="m") for f in case.files]
    else:
        scans = [sample.points for sample in generate_growth_series(case.species, case.seed, case.sessions, case.days)]
    return _PlantSeries(scans, case.carry_unseen)


def _arm_rows(sessions) -> list[dict]:
    """Each session's row without its arm (the runner names it: ``method``)."""
    return [{k: v for k, v in session.row.items() if k != "arm"} for session in sessions]


def _arm(name: str):
    def run(series: _PlantSeries, config):
        return _arm_rows(season_sessions(series.scans, config, (name,), carry_unseen=series.carry_unseen))
    return run


for _name, _help in (("truth", "each session from the previous day's ground-truth scan (the paper's protocol)"),
                     ("own", "each session from what the previous session's own views reconstructed (closed loop)"),
                     ("none", "no prior: the geometric NBV until it reaches the coverage target")):
    SEASON_ARMS.register(_name, _help, default=True)(_arm(_name))


def tables(raw: pd.DataFrame) -> dict:
    """Per session and arm (means over the plants), and per season: total views, the lowest
    coverage of any session, and how far the fused model's Chamfer distance drifted (last session
    minus the first); where the plans predicted their coverage (one-shot plans below 1), how their
    true coverage fell against it (:func:`tpvp.setcover.miss_model.plan_summary`)."""
    rows = raw.rename(columns={"method": "arm"})
    per_session = mean_std(rows, ["view_space", "replan_after", "session", "arm"],
                           columns=("views", "coverage", "path_length_m", "chamfer_fused_mm",
                                    "registration_chamfer_mm", "prior_missing"))
    season = rows.groupby(["view_space", "replan_after", "plant", "arm"], sort=False).agg(
        sessions=("session", "size"), total_views=("views", "sum"), lowest_coverage=("coverage", "min"),
        chamfer_first_mm=("chamfer_fused_mm", "first"), chamfer_last_mm=("chamfer_fused_mm", "last"),
        path_length_m=("path_length_m", "sum")).reset_index()
    season["lowest_coverage"] *= 100
    season["chamfer_drift_mm"] = season["chamfer_last_mm"] - season["chamfer_first_mm"]
    season = season.round({"lowest_coverage": 2, "chamfer_first_mm": 3, "chamfer_last_mm": 3, "chamfer_drift_mm": 3,
                           "path_length_m": 2})
    written = {"season_per_session": per_session, "season_totals": season}
    if "predicted_coverage" in rows and rows["predicted_coverage"].notna().any():  # how sure the plans were
        plans = rows[rows["predicted_coverage"].notna()].rename(
            columns={"predicted_coverage": "predicted", "predicted_coverage_lower": "lower"})
        written["season_prediction"] = plan_summary(plans, by=("view_space", "replan_after", "arm"))
    return written


def _figures(folder, raw: pd.DataFrame, written: dict, config) -> None:
    plot_season(folder / "figures" / "season.png", written["season_per_session"])


SEASON_EXPERIMENTS = Experiment("season experiments", SEASON_ARMS, _series,
                                order=("view_space", "replan_after", "plant", "method", "session"), tables=tables,
                                figures=_figures, reference=f"{__name__}:SEASON_EXPERIMENTS")


def run_season_experiments(cases, arms=ARMS, config: PlantConfig | None = None, cache_dir=None, workers: int = 1,
                           progress: bool = True) -> pd.DataFrame:
    """Every (plant, arm) season, cached and resumable like the other experiments; the raw table."""
    return runner.run_experiments(SEASON_EXPERIMENTS, cases, arms, config or make_config("plant"), cache_dir,
                                  workers, progress)


# --------------------------------------------------------------------------------------------------
# greenhouse rows
# --------------------------------------------------------------------------------------------------

#: A row's season: the rooms, the scans of each (generated, one per date), and the ``none`` arm's
#: stopping coverage: a row is planned for all of its 4 cm planning surface (coverage target 1),
#: which reaches 99.3 % on average (Table VI); the block-wise NBV (the rows' sequential NBV) runs
#: until it sees 99 % of the oracle, or :data:`ROW_NONE_MAX_VIEWS`.
ROOMS = ("room1", "room4")
ROW_SESSIONS = 5
ROW_NONE_TARGET = 0.99
ROW_NONE_MAX_VIEWS = 500
ROW_QUICK = {"rooms": ("room1",), "sessions": 3}
ROW_SEASON_ARMS = Registry("row season arm")


def row_season_sessions(series, config, arms=ARMS, name: str = "row", cache_dir=None):
    """A row's sessions per arm (:func:`chained_sessions`): ``series``: the row's scans in order
    (room frame, metres); the ``own`` prior is what the previous session's passive sweep and
    planned views saw (the observed points of its voxels); ``none`` is the block-wise NBV until
    :data:`ROW_NONE_TARGET`. ``cache_dir``: the oracles' disk cache."""
    def session(prior, today, day, arm):
        scene = build_row_scene(prior, today, config, cache_dir=cache_dir,
                                names=(f"{name} day {day} ({arm} prior)", f"{name} day {day + 1}"))
        warped = None
        if arm == "none":
            run = blockwise_nbv(scene.grid, scene.room, ROW_NONE_MAX_VIEWS, config.blockwise, sensor=config.sensor,
                                seed=config.seed, progress=False)
            curve = run.coverage_curve(scene.oracle)
            reached = np.flatnonzero(curve >= ROW_NONE_TARGET - 1e-12)
            views = int(reached[0]) if len(reached) else len(run)
            coverage, path_length = float(curve[views]), run.path_after(views)
            seen = np.flatnonzero(run.covered_after(views))
            registration = missing = float("nan")
        else:
            result = run_row_case(scene, config)
            views, coverage, path_length = result.n_views, result.coverage, result.path_length
            seen = np.union1d(execute(scene, result.positions, result.look_ats), scene.passive_seen)
            warped = result.transfer.alignment.warped
            registration = 1e3 * result.transfer.alignment.chamfer_after
            missing = prior_missing(scene, warped, config.gt_resolution)
        fused = observed_points(scene.grid, scene.current)[seen]
        row = {"session": day + 1, "arm": arm, "views": views, "coverage": coverage, "path_length_m": path_length,
               "chamfer_fused_mm": 1e3 * chamfer_distance(fused, scene.current),
               "registration_chamfer_mm": registration, "prior_missing": missing,
               "prior_points": 0 if arm == "none" else len(prior)}
        return SeasonSession(scene, prior, [], fused, warped, row), fused

    return chained_sessions(series, arms, name, session)


@dataclass(frozen=True)
class RowSeasonCase:
    """One generated row's season: ``sessions`` scans of ``room`` (the ``handheld`` reference)."""

    room: str
    seed: int = 0
    sessions: int = ROW_SESSIONS
    point_spacing: float = 0.004

    def config(self, base):
        return with_overrides(base, {"view_space": self.room})

    def labels(self) -> dict:
        return {"plant": f"{self.room}-generated-{self.seed}", "room": self.room, "seed": self.seed,
                "view_space": self.room, "replan_after": 0}


def row_season_cases(quick: bool = False, rooms=ROOMS, seeds=(0,), sessions: int = ROW_SESSIONS) -> list:
    if quick:
        rooms, sessions = ROW_QUICK["rooms"], ROW_QUICK["sessions"]
    return [RowSeasonCase(room, int(seed), int(sessions)) for room in rooms for seed in seeds]


@dataclass(frozen=True)
class _RowSeries:
    scans: list
    cache_dir: str | None


def _row_series(case: RowSeasonCase, case_config, cache_dir=None) -> _RowSeries:
    room = room_config(case.room)
    scans = [reference_points(s.points, room, "handheld")
             for s in generate_row_sessions(case.room, case.seed, case.sessions, case.point_spacing)]
    return _RowSeries(scans, str(Path(cache_dir) / "oracles") if cache_dir else None)


def _row_arm(name: str):
    def run(series: _RowSeries, config):
        return _arm_rows(row_season_sessions(series.scans, config, (name,), cache_dir=series.cache_dir))
    return run


for _name, _help in (("truth", "each session from the previous day's ground-truth scan (the paper's protocol)"),
                     ("own", "each session from what the previous session's passive sweep and planned views saw"),
                     ("none", f"no prior: the block-wise NBV until {100 * ROW_NONE_TARGET:g} % of the oracle")):
    ROW_SEASON_ARMS.register(_name, _help, default=True)(_row_arm(_name))

ROW_SEASON_EXPERIMENTS = Experiment("row season experiments", ROW_SEASON_ARMS, _row_series,
                                    order=("view_space", "plant", "method", "session"), tables=tables,
                                    figures=_figures, reference=f"{__name__}:ROW_SEASON_EXPERIMENTS")


def run_row_season_experiments(cases, arms=ARMS, config=None, cache_dir=None, workers: int = 1,
                               progress: bool = True) -> pd.DataFrame:
    """Every (row, arm) season, cached and resumable; the raw table."""
    return runner.run_experiments(ROW_SEASON_EXPERIMENTS, cases, arms, config or make_config("row"), cache_dir,
                                  workers, progress)
