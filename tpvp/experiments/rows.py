"""The greenhouse-row experiments of the paper (Tables V-VI): cases x methods, cached, in parallel.

A *case* is one consecutive session pair of one row (:class:`tpvp.simulate.row_cases.RowCase`;
default: generated rows of room1 and room4, five sessions each, 4 pairs per row = 8 cases; or the
real rows of a cleaned dataset folder). A
*method* is a named entry of :data:`ROW_METHODS`, ``method(scene, config) -> rows``, that turns a
case's scene into result rows; what it sweeps (covering voxels, budgets, repetitions) is in the one
:class:`tpvp.config.RowConfig` (``protocol``, ``pose_noise``, ``blockwise``). The runner, the cache
and the parallel execution are those of the plant experiments (:mod:`tpvp.experiments.runner`).
"""

from __future__ import annotations

import time
from dataclasses import replace
from functools import lru_cache
from pathlib import Path

import numpy as np
import pandas as pd

from tpvp.config import RowConfig
from tpvp.config_loading import make_config
from tpvp.experiments import runner
from tpvp.experiments.results import mean_std
from tpvp.experiments.pose_noise import passive_map, pose_noise_study, summarise
from tpvp.experiments.runner import Experiment, shared
from tpvp.nbv.blockwise import blockwise_nbv
from tpvp.registry import Registry
from tpvp.simulate.greenhouse import (build_row_scene, candidate_truth, random_selection, row_candidates, row_coverage,
                                      row_transfer, run_row_case, upper_limit)
from tpvp.simulate.row_cases import RowCase
from tpvp.synthetic.scan import REFERENCES
from tpvp.viewspace.lookat import PRIORS
from tpvp.viewspace.priors import AUTHORS_PRIORS
from tpvp.visibility import coverage_ratio
from tpvp.viz.rows import plot_blockwise_prefix, plot_row_frontier

PREFIX_STEP = 10  # views between the points of Block-wise NBV's prefix curve
PAPER_TABLE = Path(__file__).resolve().parent.parent / "data" / "paper" / "greenhouse_rows.csv"
PAPER_POSE_NOISE = PAPER_TABLE.with_name("pose_noise.csv")
PAPER_TIMING = PAPER_TABLE.with_name("row_timing.csv")

ROW_METHODS = Registry("row experiment method")


# --------------------------------------------------------------------------------------------------
# methods
# --------------------------------------------------------------------------------------------------

def _transfer(scene, config):
    return shared(scene, ("transfer", repr(config.registration), repr(config.inflation)),
                   lambda: row_transfer(scene, config))


def _candidates(scene, prior, config):
    def compute():
        t = time.perf_counter()
        candidates = row_candidates(scene, prior, config, _transfer(scene, config) if prior == "transfer" else None)
        return candidates, candidate_truth(scene, candidates), time.perf_counter() - t

    return shared(scene, ("candidates", prior, repr(config.targets)), compute)


@ROW_METHODS.register("coarse", "the passive sweep alone (15 fixed views)")
def coarse(scene, config):
    return [{"views": len(scene.room.initial_positions), "coverage": row_coverage(scene, []),
             "path_length_m": scene.room.passive_cost, "seconds_planning": 0.0}]


@ROW_METHODS.register("ours", "the paper's method at each covering voxel (passive warm start included)")
def ours(scene, config):
    rows = []
    for resolution in config.protocol.cover_resolutions:
        case_config = replace(config, selection=replace(config.selection, cover_resolution=float(resolution)))
        result = run_row_case(scene, case_config, transferred=_transfer(scene, config))
        rows.append({"prior": "transfer", "cover_resolution_cm": round(100 * resolution, 3), **result.summary()})
    return rows


def _random(prior):
    def method(scene, config):
        candidates, truth, seconds = _candidates(scene, prior, config)
        return [{"prior": prior, **random_selection(scene, candidates, truth, budget, repetition, config,
                                                    with_passive=prior != "obb"), "seconds_candidates": seconds}
                for budget in config.protocol.budgets for repetition in range(config.protocol.repetitions)]
    return method


for _prior in PRIORS:
    ROW_METHODS.register(f"prior-{_prior}-random", f"{_prior} look-at prior, 800 candidates, random selection")(
        _random(_prior))


@ROW_METHODS.register("upper-limit", "Table V: the share of the oracle all 800 candidates of each prior reach")
def upper_limit_rows(scene, config):
    rows = []
    for prior in PRIORS:
        candidates, truth, seconds = _candidates(scene, prior, config)
        rows.append({"prior": prior, "coverage": upper_limit(scene, truth), "views": len(candidates),
                     "seconds_candidates": seconds})
    return rows


@ROW_METHODS.register("blockwise-nbv", "sequential block-wise NBV (Zaenker et al. 2021); one run per budget "
                                          "(protocol.nbv_runs = prefix: prefixes of one run)")
def blockwise(scene, config):
    budgets = config.protocol.nbv_budgets
    separate = config.protocol.nbv_runs == "separate"
    # A run of its own budget plans its block quotas for that budget (every block visited); the
    # prefixes of one run follow the quotas of blockwise.plan_views.
    blockwise_config = replace(config.blockwise, plan_views=None) if separate else config.blockwise
    runs = {budget: blockwise_nbv(scene.grid, scene.room, budget, blockwise_config, sensor=config.sensor,
                                  seed=config.seed) for budget in (budgets if separate else [max(budgets)])}
    rows = []
    for budget in budgets:
        run = runs[budget if separate else max(budgets)]
        rows.append({"budget": int(budget), "views": int(budget),
                     "coverage": coverage_ratio(np.flatnonzero(run.covered_after(budget)), scene.oracle),
                     "path_length_m": run.path_after(budget), "seconds_planning": float(np.sum(run.seconds[:budget])),
                     "seconds_per_iteration": float(np.mean(run.seconds[:budget]))})
    # The prefix curve of the largest run (every PREFIX_STEP views), for the figure, not Table VI.
    longest = runs[max(budgets)]
    curve = longest.coverage_curve(scene.oracle)
    rows += [{"prefix_of": int(max(budgets)), "views": int(n), "coverage": float(curve[n]),
              "path_length_m": longest.path_after(n)} for n in range(PREFIX_STEP, max(budgets) + 1, PREFIX_STEP)]
    return rows


@ROW_METHODS.register("pose-noise", "Table VII: Ours' executed views with pose noise, fused with and without ICP")
def pose_noise(scene, config):
    noise = config.pose_noise
    case_config = replace(config, selection=replace(config.selection, cover_resolution=noise.cover_resolution))
    plan = run_row_case(scene, case_config, transferred=_transfer(scene, config))
    passive = passive_map(scene.grid, scene.room.initial_positions, scene.room.initial_look_ats, scene.sensor)
    # The ground-truth surface: the current session's points (1 cm voxel centroids), not the voxel
    # centres a view measures, so a perfect fusion still sits a few mm from it, as in the paper.
    table = pose_noise_study(scene.current, scene.grid, passive, plan.positions, plan.look_ats, noise, scene.sensor)
    return [{"views": plan.n_views, "cover_resolution_cm": round(100 * noise.cover_resolution, 3), **row}
            for row in table.to_dict(orient="records")]


@ROW_METHODS.register("upper-limit-authors", "Table V with the authors' own look-at files (gap_1) of the same date")
def upper_limit_authors(scene, config):
    rows = []
    for prior in AUTHORS_PRIORS:
        candidates, truth, seconds = _candidates(scene, f"authors-{prior}", config)
        rows.append({"prior": f"authors-{prior}", "coverage": upper_limit(scene, truth), "views": len(candidates),
                     "seconds_candidates": seconds})
    return rows


ALL_METHODS = ("coarse", "blockwise-nbv", "ours", "prior-obb-random", "prior-passive-random", "prior-transfer-random",
               "upper-limit")


# --------------------------------------------------------------------------------------------------
# runner
# --------------------------------------------------------------------------------------------------


@lru_cache(maxsize=1)
def _scene(case: RowCase, config: RowConfig, oracle_cache):
    previous, current = case.load()
    return build_row_scene(previous, current, config, names=(f"{case.name} (previous)", f"{case.name} (current)"),
                           cache_dir=oracle_cache, date=case.date)


def scene_columns(scene) -> dict:
    return {"oracle_voxels": len(scene.oracle), "seconds_oracle": scene.timings.get("oracle", 0.0),
            "oracle_cached": scene.oracle_cached}




def run_row_experiments(cases, methods=ALL_METHODS, config: RowConfig | None = None, cache_dir=None, workers: int = 1,
                        progress: bool = True, scheduler=None) -> pd.DataFrame:
    """Every (case, method) task (:func:`tpvp.experiments.runner.run_experiments`); the raw table.
    What the methods sweep is ``config.protocol`` (and ``config.pose_noise``)."""
    return runner.run_experiments(ROW_EXPERIMENTS, cases, methods, config or make_config("row"), cache_dir, workers,
                                  progress, scheduler)


def cached_row_experiments(cases, methods, config: RowConfig | None = None, cache_dir=None) -> pd.DataFrame | None:
    """:func:`run_row_experiments`' table from the cache when every (case, method) is there, else None."""
    return runner.cached_experiments(ROW_EXPERIMENTS, cases, methods, config or make_config("row"), cache_dir)


# --------------------------------------------------------------------------------------------------
# tables
# --------------------------------------------------------------------------------------------------


def paper_values() -> pd.DataFrame:
    """Tables V and VI of the paper (coverage in %, path in m)."""
    return pd.read_csv(PAPER_TABLE)


def paper_pose_noise() -> pd.DataFrame:
    """Table VII of the paper (Chamfer in mm, precision / recall / F1 in %)."""
    return pd.read_csv(PAPER_POSE_NOISE)


def paper_timing() -> pd.DataFrame:
    """The paper's planning times in rows (14 cores)."""
    return pd.read_csv(PAPER_TIMING)


def tables(raw: pd.DataFrame) -> dict:
    """Table V (upper limit per prior), Table VI (views, coverage, path per method and budget or
    covering voxel; random baselines averaged over repetitions first), planning time, each with the
    paper's numbers beside ours."""
    raw = raw.copy()
    for column in ("prior", "budget", "cover_resolution_cm", "views", "coverage", "path_length_m",
                   "seconds_planning", "seconds_task"):
        if column not in raw:
            raw[column] = np.nan
    if "reference" not in raw:  # rows cached before the reference was a case label
        raw["reference"] = "candidates"
    # the references in REFERENCES order, the dataset's last (groups keep their first appearance)
    raw = raw.sort_values("reference", kind="stable", key=lambda r: r.map({n: i for i, n in enumerate(REFERENCES)}))
    paper = paper_values()
    upper = mean_std(raw[raw["method"].isin(["upper-limit", "upper-limit-authors"])], ["source", "reference", "prior"],
                      columns=("coverage", "views"))
    upper = upper.merge(paper[paper["table"] == "V"][["prior", "coverage_mean", "coverage_std"]]
                        .rename(columns={"coverage_mean": "paper_coverage_mean", "coverage_std": "paper_coverage_std"}),
                        on="prior", how="left")
    curve = raw["prefix_of"].notna() if "prefix_of" in raw else pd.Series(False, index=raw.index)
    main = raw[~raw["method"].isin(["upper-limit", "upper-limit-authors"]) & ~curve].copy()
    keys = ["source", "reference", "method", "budget", "cover_resolution_cm"]
    # Repetitions of a random baseline: one value per case first, then mean ± std across cases.
    per_case = main.groupby(keys + ["case"], dropna=False, sort=False)[["views", "coverage", "path_length_m"]] \
        .mean().reset_index()
    table6 = mean_std(per_case, keys)
    paper6 = paper[paper["table"] == "VI"][["method", "budget", "cover_resolution_cm", "views_mean", "coverage_mean",
                                            "path_mean"]].rename(columns={"views_mean": "paper_views",
                                                                          "coverage_mean": "paper_coverage",
                                                                          "path_mean": "paper_path_length_m"})
    table6 = table6.merge(paper6, on=["method", "budget", "cover_resolution_cm"], how="left")
    timing_columns = [c for c in ("seconds_planning", "seconds_registration", "seconds_targets", "seconds_visibility",
                                  "seconds_selection", "seconds_path", "seconds_per_iteration", "seconds_oracle",
                                  "seconds_task") if c in raw]
    timing = mean_std(main[main["method"] != "pose-noise"], ["source", "reference", "method", "cover_resolution_cm"],
                       columns=timing_columns)
    out = {"table5_upper_limit": upper, "table6_coverage_effort": table6[table6["method"] != "pose-noise"],
           "planning_time": timing}
    if curve.any():
        out["blockwise_prefix_curve"] = mean_std(raw[curve], ["source", "reference", "prefix_of", "views"],
                                                 columns=("coverage", "path_length_m"))
    noise = raw[raw["method"] == "pose-noise"]
    if len(noise):
        out["table7_pose_noise"] = pd.concat([summarise(rows).assign(source=source, reference=reference)
                                              for (source, reference), rows in noise.groupby(["source", "reference"])],
                                             ignore_index=True)
    return out


def _figures(folder, raw: pd.DataFrame, written: dict, config: RowConfig) -> None:
    """The coverage-path frontier and, with Block-wise NBV's rows, its prefix curve."""
    plot_row_frontier(folder / "figures" / "coverage_path_frontier.png", written["table6_coverage_effort"])
    if "blockwise_prefix_curve" in written:
        plot_blockwise_prefix(folder / "figures" / "blockwise_prefix_curve.png",
                              written["blockwise_prefix_curve"], written["table6_coverage_effort"], paper_values())


# The case's oracle is cached beside the rows (cache_dir/oracle) or in the default cache folder.
ROW_EXPERIMENTS = Experiment("row experiments", ROW_METHODS, _scene, order=("room", "previous_session", "method"),
                             scene_columns=scene_columns, tables=tables,
                             paper={"paper_values": paper_values, "paper_pose_noise": paper_pose_noise},
                             figures=_figures, reference=f"{__name__}:ROW_EXPERIMENTS")
