"""The individual-plant experiments of the paper (Tables I-IV): cases x methods, cached, in parallel.

A *case* is one session pair of one plant in one view space, rotation and initial view (the paper's
protocol: 2 species x 3 instances x 2 rotations x 3 initial views per view space). A *method* is a
named entry of :data:`PLANT_METHODS` that turns a case's scene into result rows. Every
(case, method) task is independent; its rows are cached on disk (Parquet, atomic writes) under a
key hashing the case, the method, the resolved configuration, the package version and its source
code, so a changed method never reuses stale rows, an interrupted run resumes, and a finished one
re-renders instantly.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from functools import lru_cache
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import sparse

from tpvp.config import PlantConfig
from tpvp.config_loading import make_config, with_overrides
from tpvp.errors import ConfigError, InputFileError
from tpvp.experiments.baselines import nbv_curve
from tpvp.experiments.comparison import write_comparison_files
from tpvp.experiments import runner
from tpvp.experiments.results import mean_std
from tpvp.experiments.runner import Experiment, shared
from tpvp.io import read_point_cloud
from tpvp.learning.dataset import VIEWS
from tpvp.learning.methods import learned_one_shot
from tpvp.metrics import chamfer_distance
from tpvp.registry import Registry
from tpvp.scene.organs import LABEL_KINDS, ORGANS, organ_codes, part_organ_codes
from tpvp.scene.samples import load_sample
from tpvp.setcover.partial import partial_set_cover
from tpvp.simulate.optimum import optimum
from tpvp.simulate.single_plant import added_coverage, build_scene, rank_of, run_case, transfer
from tpvp.synthetic.plants import generate_session_pair
from tpvp.visibility import covered_voxels
from tpvp.viz.experiments import plot_coverage_effort, plot_species_bars

SPECIES = ("tomato", "maize")
GENERATED_SEEDS = (0, 1, 2)
ROTATIONS = (0.0, 45.0)
INITIAL_VIEWS = (17, 8, 21)
VIEW_SPACES = ("hemisphere", "sphere")
GMC_BUDGETS = (5, 10, 15, 20)
PAPER_TABLE = Path(__file__).resolve().parent.parent / "data" / "paper" / "individual_plant.csv"

PLANT_METHODS = Registry("plant experiment method")


@dataclass(frozen=True)
class Instance:
    """One session pair: generated (species + seed), bundled (the real tomato pair) or a pair of a
    prepared dataset (``python -m data_tools pheno4d prepare``: two metric PLY files)."""

    name: str
    species: str
    source: str  # "generated", "bundled" or "dataset"
    seed: int = 0
    previous_file: str = ""
    current_file: str = ""

    def load(self) -> tuple[np.ndarray, np.ndarray]:
        return _read_instance(self)[:2]

    def organs(self) -> tuple:
        """The organ codes (:mod:`tpvp.scene.organs`) of both sessions' points, or ``(None, None)``:
        a generated pair's parts, a dataset's labels as its manifest's ``label_kind`` says."""
        return _read_instance(self)[2:]


@lru_cache(maxsize=4)
def _read_instance(instance: Instance) -> tuple:
    """``(previous points, current points, previous organs, current organs)``, each scan read once."""
    if instance.source == "generated":
        pair = generate_session_pair(instance.species, instance.seed, days=2.0)
        return (pair.previous.points, pair.current.points,
                *(part_organ_codes(s.part_kinds, s.part) for s in (pair.previous, pair.current)))
    if instance.source == "bundled":
        return load_sample("tomato_0305"), load_sample("tomato_0306"), None, None
    files = [Path(instance.previous_file), Path(instance.current_file)]
    (previous, previous_labels), (current, current_labels) = (read_point_cloud(f, units="m", return_labels=True)
                                                              for f in files)
    kind = _label_kind(files[0])
    organs = [None if kind not in LABEL_KINDS or labels is None else organ_codes(labels, kind)
              for labels in (previous_labels, current_labels)]
    return previous, current, *organs


def _label_kind(file: Path) -> str:
    """What the labels of a prepared dataset's scan mean: its manifest's ``label_kind`` ("none"
    without one, as an older dataset has)."""
    manifest = file.parent.parent / "manifest.csv"
    if not manifest.is_file():
        return "none"
    table = pd.read_csv(manifest)
    if "label_kind" not in table.columns:
        return "none"
    kinds = table.loc[table["file"] == f"{file.parent.name}/{file.name}", "label_kind"]
    return str(kinds.iloc[0]) if len(kinds) and isinstance(kinds.iloc[0], str) else "none"


@dataclass(frozen=True)
class Case:
    instance: Instance
    view_space: str
    rotation_deg: float
    initial_view: int

    def config(self, base: PlantConfig) -> PlantConfig:
        return with_overrides(base, {"view_space": self.view_space, "initial_view": self.initial_view,
                                     "scene.rotation_deg": float(self.rotation_deg)})

    def labels(self) -> dict:
        return {"instance": self.instance.name, "species": self.instance.species, "source": self.instance.source,
                "view_space": self.view_space, "rotation_deg": self.rotation_deg, "initial_view": self.initial_view}


# --------------------------------------------------------------------------------------------------
# instances and cases
# --------------------------------------------------------------------------------------------------


def generated_instances(seeds=GENERATED_SEEDS, species=SPECIES) -> list[Instance]:
    """The default offline instances: generated tomato and maize pairs with fixed seeds."""
    return [Instance(f"{sp}-generated-{seed}", sp, "generated", seed) for sp in species for seed in seeds]


def bundled_instance() -> Instance:
    """The bundled real tomato pair (Pheno4D 03-05 -> 03-06), reported on its own rows."""
    return Instance("tomato-real-0305-0306", "tomato", "bundled")


def dataset_table(folder, plants=None) -> pd.DataFrame:
    """A prepared dataset's ``pairs.csv`` (only ``plants`` when given), every listed file checked."""
    folder = Path(folder)
    table_path = folder / "pairs.csv"
    if not table_path.is_file():
        raise InputFileError(f"{folder}: no pairs.csv; prepare the dataset with python -m data_tools pheno4d prepare")
    try:
        table = pd.read_csv(table_path)
    except (OSError, ValueError, pd.errors.ParserError) as exc:
        raise InputFileError(f"{table_path}: not a readable pairs table ({exc})") from None
    needed = {"plant", "species", "previous_date", "current_date", "previous_file", "current_file"}
    if missing := needed - set(table.columns):
        raise InputFileError(f"{table_path}: missing columns {', '.join(sorted(missing))}")
    table = table.reset_index(drop=True)
    if plants:
        table = table[table["plant"].isin(list(plants))]
    for name in (*table["previous_file"], *table["current_file"]):
        if not (folder / name).is_file():
            raise InputFileError(f"{folder / name}: listed in {table_path} but missing")
    return table


def dataset_instances(folder, plants=None, pairs=None, paper_subset: bool = False) -> list[Instance]:
    """Every pair of a prepared dataset's ``pairs.csv`` (or the selected ``plants`` / ``pairs``
    row numbers; ``paper_subset``: plants 1-3 of each species, their first pair)."""
    folder = Path(folder)
    table_path = folder / "pairs.csv"
    table = dataset_table(folder, plants)
    if pairs:
        table = table.loc[[i for i in pairs if i in table.index]]
    if paper_subset:
        number = table["plant"].map(lambda p: int(m.group(1)) if (m := re.search(r"(\d+)$", str(p))) else 0)
        table = table[number.between(1, 3)].groupby("plant", sort=True).head(1)
    if table.empty:
        raise ConfigError(f"{table_path}: the selection (plants={plants}, pairs={pairs}, paper_subset={paper_subset}) "
                          f"selects no pair")
    out = []
    for row in table.itertuples():
        files = [folder / f for f in (row.previous_file, row.current_file)]
        out.append(Instance(f"{row.plant}-{row.previous_date}-{row.current_date}", str(row.species).lower(),
                            "dataset", 0, str(files[0]), str(files[1])))
    return out


def default_cases(quick: bool = False, dataset=None, plants=None, pairs=None, paper_subset: bool = False,
                  view_spaces=VIEW_SPACES, rotations=ROTATIONS, initial_views=INITIAL_VIEWS,
                  with_bundled: bool = True) -> list[Case]:
    """The paper's protocol on the generated pairs (72 cases) plus the bundled real pair on its own
    rows, or on a prepared dataset (``dataset``). ``quick``: one tomato and one maize pair,
    rotation 0, initial view 17 (a few cases for notebooks and CI)."""
    if dataset is not None:
        instances = dataset_instances(dataset, plants, pairs, paper_subset)
    else:
        instances = generated_instances(seeds=(0,) if quick else GENERATED_SEEDS)
        if with_bundled and not quick:
            instances.append(bundled_instance())
    if quick:
        rotations, initial_views = rotations[:1], initial_views[:1]
    return case_list(instances, view_spaces, rotations, initial_views)


def case_list(instances, view_spaces=VIEW_SPACES, rotations=ROTATIONS, initial_views=INITIAL_VIEWS) -> list[Case]:
    """Every combination, in a stable order."""
    cases = [Case(i, v, float(r), int(k)) for v in view_spaces for i in instances for r in rotations for k in initial_views]
    if not cases:
        raise ConfigError("the case list is empty: give at least one instance, view space, rotation and initial view")
    return cases


# --------------------------------------------------------------------------------------------------
# methods: scene + case config -> rows
# --------------------------------------------------------------------------------------------------


def _optimum_for_coverage(scene, result, config) -> dict:
    """The fewest views (same initial view, perfect knowledge) that see as many oracle voxels as
    ``result``'s views did: the physical limit for the coverage the method actually reached."""
    oracle = np.asarray(scene.oracle)
    reached = int(np.isin(oracle, covered_voxels(scene.truth_visibility, result.order)).sum())
    best = partial_set_cover(sparse.csr_matrix(scene.truth_visibility)[:, oracle], reached,
                             executed=[result.executed_views[0]], config=config.selection.set_cover)
    return {"optimum_views_same_coverage": best.objective + 1, "optimum_same_coverage_optimal": best.optimal}


def warm_up_rank(scene, executed) -> dict:
    """Rank (1 = a best view) of the first warm-up NBV by the coverage it truly adds to the initial view."""
    if len(executed) < 2:
        return {}
    return {"warm_up_rank": rank_of(added_coverage(scene, executed[:1]), executed[:1], executed[1])}


def _case_row(result, scene, config) -> dict:
    return {"views": result.n_views, "coverage": result.coverage, "path_length_m": result.path_length,
            **{f"coverage_{organ}": value for organ, value in result.organ_coverage.items()},
            "coverage_after_warm_up": result.coverage_captured, **warm_up_rank(scene, result.executed_views),
            **_optimum_for_coverage(scene, result, config),
            "chamfer_before_mm": 1e3 * result.chamfer_before, "chamfer_after_mm": 1e3 * result.chamfer_after,
            # Table IV: the transferred model against the current ground-truth surface
            "chamfer_truth_mm": 1e3 * chamfer_distance(result.clouds["warped"], scene.current),
            "optimal": bool(result.selection.optimal and result.path.optimal), "status": result.selection.status,
            "seconds_planning": result.timings["planning"],
            "seconds_total": sum(result.timings[k] for k in ("warm_up", "registration", "planning"))}


def shared_transfer(scene, config):
    """The warm-up + registration of ``scene`` under ``config``, computed once per process: Ours and
    Ours w/o inflation (and the two initial-view-only variants) differ only after registration."""
    key = ("transfer", config.initial_view, repr(config.nbv), repr(config.registration))
    return shared(scene, key, lambda: transfer(scene, config))


#: The one-shot methods (Ours and its variants): name -> the configuration overrides it runs with
#: (:func:`register_one_shot`).
ONE_SHOT_METHODS: dict[str, dict] = {}


def method_config(config: PlantConfig, method: str) -> PlantConfig:
    """``config`` with the overrides of the one-shot ``method`` (:data:`ONE_SHOT_METHODS`)."""
    if method not in ONE_SHOT_METHODS:
        raise KeyError(f"unknown one-shot method {method!r}; choose from {', '.join(ONE_SHOT_METHODS)}")
    return with_overrides(config, ONE_SHOT_METHODS[method])


def register_one_shot(name: str, overrides: dict, help: str, default: bool = True) -> None:
    """A one-shot method: the paper's method on a case with the configuration ``overrides``
    (e.g. ``{"inflation.enabled": False}``), its warm-up and registration shared with the other
    one-shot methods that run the same ones. ``default``: in the paper's protocol (Tables I-IV)."""
    def method(scene, config):
        config = method_config(config, name)
        return [_case_row(run_case(scene, config, transferred=shared_transfer(scene, config)), scene, config)]
    PLANT_METHODS.register(name, help, default)(method)
    ONE_SHOT_METHODS[name] = dict(overrides)


register_one_shot("ours", {}, "the paper's method: warm-up NBV, registration, inflation, set cover, TSP")
register_one_shot("ours-no-inflation", {"inflation.enabled": False},
                  "planning on the aligned previous session only (Table III)")
register_one_shot("initial-view-only", {"nbv.warm_up_views": 0},
                  "registration on the initial view, no warm-up NBV (Table IV)")
register_one_shot("initial-view-only-no-inflation", {"nbv.warm_up_views": 0, "inflation.enabled": False},
                  "initial view only, without inflation")
register_one_shot("one-shot-no-prior", {"registration.method": "no-prior", "inflation.enabled": False},
                  "set cover + TSP on the coarse reconstruction alone (no previous session)")
register_one_shot("ours-pc-nbv", {"nbv.method": "pc-nbv"}, "the paper's method with the learned PC-NBV warm-up view",
                  default=False)


@PLANT_METHODS.register("gmc", "GMC-style sequential NBV from the initial view; the whole 1..20 curve "
                                "(tie_picks: the picks so far that the tie rule decided)", default=True)
def gmc(scene, config):
    curve = nbv_curve(scene, config, max_views=max(GMC_BUDGETS))
    tie_picks = np.cumsum(curve["tied"].to_numpy() > 1)  # picks so far that a tie decided (gmc.tie_break)
    return [{"budget": int(row.views), "views": int(row.views), "coverage": row.coverage,
             "path_length_m": row.path_length, "seconds_planning": float(curve["seconds"][:i + 1].sum()),
             "tie_picks": int(tie_picks[i])}
            for i, row in enumerate(curve.itertuples())]


@PLANT_METHODS.register("optimum", "the exact optimum with perfect knowledge of today's plant (100 % and 98 %)",
                        default=True)
def exact_optimum(scene, config):
    table = optimum(scene, config, targets=(1.0, 0.98))
    return [{"target": row.target, "views": int(row.views), "coverage": row.coverage, "path_length_m": row.path_length,
             "optimal": bool(row.optimal), "gap": row.gap, "seconds_planning": row.seconds}
            for row in table.itertuples()]


NOT_APPLICABLE = "not applicable: the learned planners know the 32 hemisphere views only"


def _learned(labels: str):
    def method(scene, config):
        if len(scene.view_space) < VIEWS:  # a row that says why, not a failed experiment
            return [{"status": NOT_APPLICABLE}]

        # the published system: one PC-NBV view before the network
        config = with_overrides(config, {"nbv.method": "pc-nbv", "nbv.warm_up_views": 1})
        row = learned_one_shot(scene, config, labels)
        del row["planned_order"], row["obstacle_radius"]
        return [{**row, **warm_up_rank(scene, row.pop("executed_views"))}]
    return method


PLANT_METHODS.register("ma-scvp", "MA-SCVP-style learned view set after one PC-NBV view (tpvp.learning)",
                       default=True)(_learned("network"))
PLANT_METHODS.register("ma-scvp-oracle", "MA-SCVP's pipeline with the exact set cover it is trained to predict",
                       default=True)(_learned("oracle"))


# --------------------------------------------------------------------------------------------------
# tasks, cache, parallel runner
# --------------------------------------------------------------------------------------------------


@lru_cache(maxsize=2)
def _scene(case_without_view: Case, config: PlantConfig):
    previous, current = case_without_view.instance.load()
    return build_scene(previous, current, config, names=(f"{case_without_view.instance.name} previous",
                                                         f"{case_without_view.instance.name} current"),
                       organs=case_without_view.instance.organs())


def case_scene(case: Case, case_config: PlantConfig, cache_dir=None):
    """The scene depends on the pair, view space and rotation only: shared by initial views and methods."""
    return _scene(replace(case, initial_view=0), replace(case_config, initial_view=0))




def run_task(case: Case, method: str, config: PlantConfig, cache_dir=None) -> pd.DataFrame:
    """The rows of one (case, method), from the cache when present; written to it otherwise."""
    return runner.run_task(PLANT_EXPERIMENTS, case, method, config, cache_dir)


def run_experiments(cases, methods, config: PlantConfig | None = None, cache_dir=None, workers: int = 1,
                    progress: bool = True, scheduler=None) -> pd.DataFrame:
    """Every (case, method) task (:func:`tpvp.experiments.runner.run_experiments`); the raw table."""
    return runner.run_experiments(PLANT_EXPERIMENTS, cases, methods, config or make_config("plant"), cache_dir,
                                  workers, progress, scheduler)


def cached_experiments(cases, methods, config: PlantConfig | None = None, cache_dir=None) -> pd.DataFrame | None:
    """:func:`run_experiments`' table from the cache when every (case, method) is there, else None."""
    return runner.cached_experiments(PLANT_EXPERIMENTS, cases, methods, config or make_config("plant"), cache_dir)


# --------------------------------------------------------------------------------------------------
# tables
# --------------------------------------------------------------------------------------------------


def paper_values() -> pd.DataFrame:
    return pd.read_csv(PAPER_TABLE)


def tables(raw: pd.DataFrame) -> dict:
    """Table I (per view space and method; GMC per budget), II (Ours per species and view space),
    III (inflation ablation per species, both view spaces pooled), IV (Chamfer of the transferred
    model to the ground truth: initial view only vs + one NBV), timing, optimum ratio. Rows of the
    real bundled pair are kept apart from the generated ones (``source``)."""
    raw = raw.copy()
    for column in ("budget", "target", "status", "views", "coverage", "path_length_m", "chamfer_truth_mm",
                   "chamfer_after_mm", "seconds_planning", "seconds_task"):
        if column not in raw:
            raw[column] = np.nan
    # rows without a result: a method pending or not applicable to the view space
    pending = raw[raw["status"].astype(str).str.startswith(("pending", "not applicable"))]
    done = raw.drop(pending.index)
    gmc_rows = done[(done["method"] == "gmc") & done["budget"].isin(GMC_BUDGETS)]
    one_shot = done[~done["method"].isin(["gmc", "optimum"])]
    table1 = pd.concat([
        mean_std(gmc_rows, ["source", "view_space", "method", "budget"]),
        mean_std(one_shot, ["source", "view_space", "method"]),
        mean_std(done[done["method"] == "optimum"], ["source", "view_space", "method", "target"]),
        pending.groupby(["source", "view_space", "method", "status"]).size().rename("cases").reset_index(),
    ], ignore_index=True)
    table1["budget"] = table1["budget"].astype("Int64")
    organs = [f"coverage_{organ}" for organ in ORGANS
              if f"coverage_{organ}" in done and done[f"coverage_{organ}"].notna().any()]
    table2 = mean_std(done[done["method"] == "ours"], ["source", "species", "view_space"],
                      columns=("views", "coverage", "path_length_m", *organs))
    table3 = mean_std(done[done["method"].isin(["ours", "ours-no-inflation"])], ["source", "species", "method"])
    table4 = mean_std(done[done["method"].isin(["ours", "initial-view-only"])], ["source", "method"],
                       columns=("chamfer_truth_mm", "chamfer_after_mm"))
    timing = mean_std(done, ["source", "method"], columns=("seconds_planning", "seconds_task"))
    return {"table1_coverage_effort": table1, "table2_plant_complexity": table2, "table3_inflation": table3,
            "table4_registration": table4, "planning_time": timing, "optimum_ratio": optimum_ratio(done)}


def optimum_ratio(done: pd.DataFrame) -> pd.DataFrame:
    """Each one-shot method's views as a ratio to the exact optimum's views for the coverage the
    method actually reached on that case (same initial view, perfect knowledge), beside the
    optimum for 98 % (compared only where the method reached 98 %)."""
    if "optimum_views_same_coverage" not in done:
        return pd.DataFrame()
    rows = done[done["optimum_views_same_coverage"].notna()].copy()
    rows["views_ratio"] = rows["views"] / rows["optimum_views_same_coverage"]
    optimum = done[done["method"] == "optimum"]
    if len(optimum):
        keys = ["instance", "view_space", "rotation_deg", "initial_view"]
        best = optimum[optimum["target"] == 0.98][keys + ["views"]].rename(columns={"views": "optimum_views_98"})
        rows = rows.merge(best, on=keys, how="left")
        rows.loc[rows["coverage"] < 0.98, "optimum_views_98"] = np.nan
        rows["views_ratio_98"] = rows["views"] / rows["optimum_views_98"]
    columns = [c for c in ("views", "coverage", "optimum_views_same_coverage", "views_ratio", "optimum_views_98",
                           "views_ratio_98") if c in rows]
    return mean_std(rows, ["source", "view_space", "method"], columns=columns)


def comparison_case(cases) -> Case:
    """The case of the comparison figure: the paper shows a sphere case; the first one listed (else
    the first case)."""
    cases = list(cases)
    return next((c for c in cases if c.view_space == "sphere"), cases[0])


def _figures(folder, raw: pd.DataFrame, written: dict, config: PlantConfig, comparison: Case | None = None) -> None:
    """The coverage-effort and per-species figures and, for a ``comparison`` case, the GMC / Ours /
    optimum comparison (figure, table, rerun recording)."""
    for source in raw["source"].unique():
        rows = raw[raw["source"] == source]
        plot_coverage_effort(folder / "figures" / f"coverage_effort_{source}.png", rows,
                             f"Coverage-effort trade-off ({source} pairs)")
    ours = written["table2_plant_complexity"]
    for source in ours["source"].unique() if len(ours) else ():
        plot_species_bars(folder / "figures" / f"views_per_species_{source}.png",
                          ours[ours["source"] == source], "views", f"Ours: views per species ({source} pairs)")
    if comparison is not None:
        case_config = comparison.config(config)
        scene = case_scene(comparison, case_config)
        write_comparison_files(folder / "comparison", scene, case_config,
                               title=f"{comparison.view_space}, {comparison.instance.name}, rotation "
                                     f"{comparison.rotation_deg:g} deg, initial view {comparison.initial_view}")


PLANT_EXPERIMENTS = Experiment("plant experiments", PLANT_METHODS, case_scene,
                               order=("view_space", "instance", "rotation_deg", "initial_view", "method"),
                               tables=tables, paper={"paper_values": paper_values}, figures=_figures,
                               reference=f"{__name__}:PLANT_EXPERIMENTS")
